"""Python environments laid out as users lay them out, for end-to-end tests.

A green run in the developer's layout proves one layout. These helpers build the
others: a copy of the repository with a venv inside it (``.venv``), a venv
beside it, a non-editable install, a student's install next to a release
folder, and an ordinary (non-root) user with Debian's own Python. Each venv
gets real copies of numpy, scipy, matplotlib and IPython (not the developer's
site-packages), because where those files lie is what the sandbox must get right.

Installs go through pip and PyPI (reachable from CI); pip's cache makes the
second one fast. Everything is made under a world-readable temporary folder so
that another user can run it.
"""

from __future__ import annotations

import os
import pwd
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
#: the user the ordinary-user tests run as (created when missing)
ORDINARY_USER = "numgrade-ci"
#: what the worker imports; installed into each venv so they live inside it
WORKER_STACK = ("numpy", "scipy", "matplotlib", "ipython")
INSTALL_TIMEOUT = 1200


@dataclass(frozen=True)
class Env:
    """A Python environment with numgrade installed, and how to run its commands."""

    python: Path
    user: str | None = None

    @property
    def bin(self) -> Path:
        return self.python.parent

    def command(self, *args: str) -> list[str]:
        """argv for running ``args[0]`` from this environment (or a path), as its user."""
        argv = [args[0] if "/" in args[0] else str(self.bin / args[0]), *args[1:]]
        if self.user is None:
            return argv
        # setpriv, not runuser or su: no PAM session, so no session or user keyring is
        # made for the user (the problem tests count the keys a submission could leave).
        return ["setpriv", f"--reuid={self.user}", f"--regid={self.user}", "--init-groups",
                "--", "env", f"HOME={home(self.user)}", "PATH=/usr/local/bin:/usr/bin:/bin", *argv]

    def run(self, *args: str, cwd: Path | None = None, timeout: float = 900,
            env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
        return subprocess.run(self.command(*args), cwd=cwd, env=self.environment(env),
                              capture_output=True, text=True, timeout=timeout)

    def environment(self, env: dict[str, str] | None = None) -> dict[str, str]:
        """This process's environment less its Python settings, plus ``env``."""
        merged = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
        merged.update(env or {})
        return merged


def shared_tempdir(prefix: str) -> Path:
    """A temporary folder every user may enter (pytest's own is mode 700 as root)."""
    path = Path(tempfile.mkdtemp(prefix=prefix))
    path.chmod(0o755)
    return path


def copy_repository(target: Path) -> Path:
    """The repository's tracked and new (not ignored) files, copied to ``target``."""
    listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT,
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = ROOT / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    _open_up(target)
    return target


def give_to(user: str, top: Path) -> Path:
    """Make ``user`` the owner of everything under ``top`` (a build writes into its source)."""
    for folder, _, files in os.walk(top):
        for path in [folder, *(os.path.join(folder, name) for name in files)]:
            shutil.chown(path, user, user)
    return top


def make_venv(where: Path, *, install: list[str], python: str = sys.executable,
              user: str | None = None, stack: bool = True, system_site: bool = False,
              cache: Path | None = None) -> Env:
    """A venv at ``where`` with ``pip install *install`` (and the worker's stack inside it).

    ``cache`` is a pip cache shared by every venv of a test run (and every user), so
    the wheels are downloaded once.
    """
    env = Env(python=where / "bin" / "python", user=user)
    venv = [python, "-m", "venv", *(["--system-site-packages"] if system_site else []), str(where)]
    _run_checked(Env(Path(python), user).command(*venv) if user else venv)
    packages = [*WORKER_STACK] if stack else []
    pip = ["python", "-m", "pip", "install", "-q", "--disable-pip-version-check"]
    if cache is not None:
        pip += ["--cache-dir", str(cache)]
    _run_checked(env.command(*pip, *packages, *install))
    return env


def home(user: str) -> str:
    return pwd.getpwnam(user).pw_dir


def ordinary_user() -> str:
    """Create (once) the unprivileged user the ordinary-user tests run as."""
    try:
        pwd.getpwnam(ORDINARY_USER)
    except KeyError:
        _run_checked(["useradd", "--create-home", "--shell", "/bin/bash", ORDINARY_USER])
    return ORDINARY_USER


def can_switch_users() -> str | None:
    """None when tests may create and become another user, else why not."""
    if os.geteuid() != 0:
        return "creating another user needs root"
    missing = [tool for tool in ("useradd", "setpriv") if shutil.which(tool) is None]
    if missing:
        return f"{' and '.join(missing)} not found"
    return None


def _open_up(top: Path) -> None:
    for directory, _, files in os.walk(top):
        os.chmod(directory, 0o755)
        for name in files:
            path = os.path.join(directory, name)
            os.chmod(path, os.stat(path).st_mode | 0o444)


def _run_checked(argv: list[str]) -> None:
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=INSTALL_TIMEOUT)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} failed ({proc.returncode}):\n"
                           f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
