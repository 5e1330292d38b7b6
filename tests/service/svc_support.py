"""Helpers of the service tests: a real server in a subprocess, a PostgreSQL cluster, WebDriver.

The WebDriver client is the same standard-library approach as
``tests/autograder/test_browser.py`` (chromedriver's W3C HTTP interface, no
Selenium), with the element commands a form-filling test needs.
"""

from __future__ import annotations

import csv
import os
import pwd
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from tests.support.webdriver import (  # noqa: F401 (re-exported for the service tests)
    CHROMEDRIVER,
    CHROMIUM,
    FLAGS,
    WebDriver,
    free_port,
    start_chromedriver,
)

ROOT = Path(__file__).resolve().parents[2]
HULL_EXAMPLES = ROOT / "assignments" / "hull" / "examples"
#: start-up imports numpy, pytest and SQLAlchemy; on a busy 2-core machine that is slow
START_TIMEOUT = 240.0


def postgres_bin() -> Path | None:
    found = shutil.which("pg_ctl")
    if found:
        return Path(found).resolve().parent
    versions = sorted(Path("/usr/lib/postgresql").glob("*/bin/pg_ctl"))
    return versions[-1].parent if versions else None


@dataclass
class PostgresCluster:
    """A throw-away cluster in a temporary folder, run by an unprivileged user."""

    folder: Path
    port: int
    user: str | None  # the OS user running it (None: ourselves, when not root)
    bin: Path

    def _run(self, *argv: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        cmd = [str(self.bin / argv[0]), *argv[1:]]
        if self.user is not None:
            cmd = ["runuser", "-u", self.user, "--", *cmd]
        return subprocess.run(cmd, check=check, capture_output=True, text=True, timeout=120)

    def start(self) -> None:
        data = self.folder / "data"
        self._run("initdb", "-D", str(data), "-A", "trust", "-U", "postgres", "--no-sync",
                  "-E", "UTF8")
        options = (f"-c listen_addresses=127.0.0.1 -c port={self.port} "
                   f"-c unix_socket_directories={self.folder} -c fsync=off "
                   "-c max_connections=200 -c synchronous_commit=off")
        self._run("pg_ctl", "-D", str(data), "-l", str(self.folder / "log"), "-w", "-t", "120",
                  "-o", options, "start")

    def stop(self) -> None:
        self._run("pg_ctl", "-D", str(self.folder / "data"), "-m", "immediate", "-w", "stop",
                  check=False)
        shutil.rmtree(self.folder, ignore_errors=True)

    def create_database(self, name: str) -> str:
        import psycopg

        with psycopg.connect(f"host=127.0.0.1 port={self.port} user=postgres dbname=postgres",
                             autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{name}"


def start_postgres() -> PostgresCluster:
    """Start a cluster; ``RuntimeError`` (skip) only when PostgreSQL is not installed."""
    binary = postgres_bin()
    if binary is None:
        raise RuntimeError("PostgreSQL is not installed (apt-get install postgresql; .ci/run does)")
    user = None
    if os.geteuid() == 0:  # postgres refuses to run as root
        try:
            pwd.getpwnam("postgres")
        except KeyError:
            raise RuntimeError("running as root and there is no 'postgres' user to run the "
                               "cluster as (Debian's postgresql package creates it)") from None
        user = "postgres"
    # pytest's temporary folders are private to root: the cluster's user could not reach
    # one, so the cluster lives in a folder of its own under the system's temporary folder
    folder = Path(tempfile.mkdtemp(prefix="numgrade-pg-"))
    if user is not None:
        shutil.chown(folder, user, user)
    cluster = PostgresCluster(folder, free_port(), user, binary)
    try:
        cluster.start()
    except subprocess.CalledProcessError as exc:
        shutil.rmtree(folder, ignore_errors=True)  # installed but broken: a failure, not a skip
        raise AssertionError(f"the PostgreSQL cluster did not start: {exc.stderr[-1500:]}") from None
    return cluster


# -- the service -------------------------------------------------------------------

def write_course(folder: Path, *, body: str, roster: list[tuple[str, str, str, str]]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with (folder / "roster.csv").open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["id", "name", "email", "role"])
        writer.writerows(roster)
    path = folder / "course.toml"
    path.write_text(body)
    return path


@dataclass
class Server:
    """``autograder serve`` in a subprocess on 127.0.0.1 and a free port."""

    course: Path
    database: str
    jobs: int = 2
    lease: float = 6.0
    port: int = field(default_factory=free_port)
    proc: subprocess.Popen[bytes] | None = None
    #: grade on this Dask cluster (``--dask``) instead of ``jobs`` local grading processes
    dask: str | None = None
    #: more options of ``autograder serve``
    options: tuple[str, ...] = ()

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self) -> "Server":
        log = (self.course.parent / "serve.log").open("ab")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "autograder", "serve", str(self.course), "--port", str(self.port),
             "--database", self.database, "--lease", str(self.lease),
             *(["--dask", self.dask] if self.dask else ["--jobs", str(self.jobs)]), *self.options],
            stdout=log, stderr=subprocess.STDOUT, cwd=self.course.parent, start_new_session=True)
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            try:
                if httpx.get(self.url + "/login", timeout=5).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"the service did not start; see {self.course.parent / 'serve.log'}:\n"
                                     + (self.course.parent / "serve.log").read_text()[-3000:])
            time.sleep(0.3)

    def kill(self) -> list[int]:
        """SIGKILL the service process only; return the ids of its child processes then."""
        assert self.proc is not None
        children = Path(f"/proc/{self.proc.pid}/task/{self.proc.pid}/children")
        pids = [int(p) for p in children.read_text().split()] if children.exists() else []
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(30)
        return pids


    def stop(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(60)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(30)

    def tokens(self) -> dict[str, str]:
        data = self.course.parent / "data" / "tokens.csv"
        with data.open() as handle:
            return {row["id"]: row["token"] for row in csv.DictReader(handle)}


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie waiting for its reaper counts as gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def upload(client: httpx.Client, url: str, token: str, assignment: str, data: bytes,
           name: str = "hull.ipynb") -> httpx.Response:
    return client.post(f"{url}/assignments/{assignment}/submissions",
                       headers={"Authorization": f"Bearer {token}", "Accept": "application/json"},
                       files={"notebook": (name, data, "application/x-ipynb+json")})


def wait_graded(client: httpx.Client, url: str, token: str, sub_id: int,
                timeout: float = 600.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        view = client.get(f"{url}/api/submissions/{sub_id}",
                          headers={"Authorization": f"Bearer {token}"}).json()
        if view["status"] not in ("queued", "running") or time.monotonic() > deadline:
            return view
        time.sleep(0.3)


# -- WebDriver ---------------------------------------------------------------------

