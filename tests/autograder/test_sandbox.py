"""Tests of :mod:`autograder.sandbox.confine` and of the modules whose steps it orders.

The policy (:mod:`autograder.sandbox.policy`), the probe of what the machine offers
(:mod:`autograder.sandbox.support`), the readable paths (:mod:`autograder.sandbox.readable`),
the Landlock ruleset (:mod:`autograder.sandbox.landlock`) and the child's environment
(:mod:`autograder.sandbox.environment`).

Each sandbox case forks a child that enters the sandbox in a temporary working
directory, tries one thing and reports over a pipe as JSON; the parent asserts.
Every child runs under a wall-clock deadline: past it, the parent kills the
child's process group, so no case can hang the suite.
"""

from __future__ import annotations

import errno
import importlib.metadata
import importlib.util
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pytest

from autograder.engine.slot import claim_slot
from autograder.errors import UsageError
from autograder.sandbox import readable
from autograder.sandbox.confine import enter_sandbox, fork_child
from autograder.sandbox.environment import clean_environment
from autograder.sandbox.landlock import SharedLandlock, shared_landlock
from autograder.sandbox.policy import IsolationPolicy, Limits
from autograder.sandbox.readable import coverable_folders, readable_paths
from autograder.sandbox.support import probe_support

REPO = Path(__file__).resolve().parents[2]
# Slots claimed as a grader claims them and held while the tests run: a grader running
# at the same time (another test run, a CI job) never uses or sweeps these user ids,
# and these children never share a user id with a grader's. Tests name them 0-5.
_CLAIMED = [claim_slot(300) for _ in range(6)]
SLOTS = [slot for slot, _ in _CLAIMED]
CHILD_DEADLINE = 20.0  # seconds of wall-clock time a forked child may take
SECRET = "hunter2-not-for-students"

DEFAULT = IsolationPolicy()
LANDLOCK_ONLY = IsolationPolicy(network_namespace=False, drop_user=False)
NAMESPACE_ONLY = IsolationPolicy(landlock=False)


# ---------------------------------------------------------------------- harness


@dataclass(frozen=True)
class Outcome:
    """What a sandboxed child reported, and how it ended."""

    report: dict[str, Any] | None
    status: int
    timed_out: bool

    @property
    def signal(self) -> int:
        return os.WTERMSIG(self.status) if os.WIFSIGNALED(self.status) else 0

    @property
    def value(self) -> Any:
        assert self.report is not None, f"the child reported nothing (status {self.status:#x})"
        assert "value" in self.report, f"the child failed: {self.report}"
        return self.report["value"]

    @property
    def error(self) -> dict[str, Any]:
        assert self.report is not None, f"the child reported nothing (status {self.status:#x})"
        assert "error" in self.report, f"the action did not raise: {self.report}"
        return self.report


def run_sandboxed(
    action: Callable[[], Any],
    workdir: Path,
    *,
    policy: IsolationPolicy = DEFAULT,
    slot: int = 0,
    exclude: Sequence[Path] = (),
    deadline: float = CHILD_DEADLINE,
    shared: bool = False,
    ruleset: SharedLandlock | None = None,
    fork: Callable[[], int] = os.fork,
) -> Outcome:
    """Fork, enter the sandbox in the child, run ``action`` there, collect the report.

    ``shared``: as the warm parent does, build the Landlock ruleset here, before the
    fork, for every working directory in ``workdir``'s parent folder (or pass one
    built already as ``ruleset``). ``fork``: how the child is forked (a plain fork,
    so that as root the child forks the relay of its PID namespace; or as the warm
    parent forks, ``confine.fork_child``).
    """
    if shared:  # what the grader guarantees: the work root holds only this child's folder
        assert os.listdir(workdir.parent) == [workdir.name], "a work root holds one folder"
        ruleset = shared_landlock(policy, workdir.parent, exclude)
    read_fd, write_fd = os.pipe()
    pid = fork()
    if pid == 0:  # the child never returns into pytest
        os.close(read_fd)
        _child_main(action, write_fd, policy, workdir, SLOTS[slot], exclude, ruleset)
    os.close(write_fd)
    try:
        data, status, timed_out = _collect(pid, read_fd, deadline)
    finally:
        os.close(read_fd)
        _kill_group(pid)
        if ruleset is not None:
            ruleset.close()
    return Outcome(json.loads(data) if data else None, status, timed_out)


def _child_main(
    action: Callable[[], Any],
    write_fd: int,
    policy: IsolationPolicy,
    workdir: Path,
    slot: int,
    exclude: Sequence[Path],
    shared: SharedLandlock | None,
) -> None:
    code = 70
    try:
        try:
            notes = enter_sandbox(policy, workdir, slot=slot, exclude=exclude, shared=shared)
        except BaseException as exc:
            report: dict[str, Any] = {"sandbox_error": repr(exc)}
        else:
            report = {"notes": list(notes), **_call(action)}
        os.write(write_fd, json.dumps(report).encode())
        code = 0
    finally:
        os._exit(code)


def _call(action: Callable[[], Any]) -> dict[str, Any]:
    try:
        return {"value": action()}
    except Exception as exc:
        return {"error": type(exc).__name__, "errno": getattr(exc, "errno", None),
                "message": str(exc)}


def _collect(pid: int, read_fd: int, deadline: float) -> tuple[bytes, int, bool]:
    chunks: list[bytes] = []
    os.set_blocking(read_fd, False)
    end = time.monotonic() + deadline
    while time.monotonic() < end:
        _drain(read_fd, chunks)
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            _drain(read_fd, chunks)
            return b"".join(chunks), status, False
        time.sleep(0.01)
    _kill_group(pid)
    _, status = os.waitpid(pid, 0)
    return b"".join(chunks), status, True


def _drain(fd: int, chunks: list[bytes]) -> None:
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            return
        if not chunk:
            return
        chunks.append(chunk)


def _kill_group(pid: int) -> None:
    """Kill whatever is left of the child's session (its group id is its pid)."""
    for kill in (os.killpg, os.kill):
        try:
            kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def require_landlock(min_abi: int, what: str) -> None:
    abi = probe_support().landlock_abi
    if abi < min_abi:
        pytest.skip(f"Landlock unavailable (ABI {abi}): {what} needs ABI {min_abi}.")


def require_root(what: str) -> None:
    if not probe_support().is_root:
        pytest.skip(f"Not running as root: {what} needs root.")


def require_policy(policy: IsolationPolicy) -> None:
    """Skip a parametrised case whose policy this machine cannot apply."""
    if policy.landlock:
        require_landlock(6, "a policy that relies on Landlock")
    if policy.network_namespace or policy.drop_user:
        require_root("a policy with a network namespace or a user switch")


@pytest.fixture
def workdir(tmp_path: Path) -> Path:
    """A working directory alone in its folder, as a slot's work root holds it."""
    path = tmp_path / "work-root" / "work"
    path.mkdir(parents=True)
    return path


@pytest.fixture
def grader_terms() -> Iterator[list[int]]:
    """Record SIGTERMs sent to this process instead of dying from them."""
    received: list[int] = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: received.append(signum))
    try:
        yield received
    finally:
        signal.signal(signal.SIGTERM, previous)


# ------------------------------------------------------------------ plain checks


def test_limits_reject_non_positive_values() -> None:
    message = r"`limits.memory_bytes` must be a positive integer; got 0"
    with pytest.raises(UsageError, match=message):
        Limits(memory_bytes=0)
    with pytest.raises(UsageError, match="`limits.cpu_seconds`"):
        Limits(cpu_seconds=True)


def test_policy_rejects_bad_settings() -> None:
    with pytest.raises(UsageError, match="`policy.base_uid`"):
        IsolationPolicy(base_uid=-1)
    with pytest.raises(UsageError, match="`policy.allowed_read`"):
        IsolationPolicy(allowed_read="/data")  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="`policy.limits`"):
        IsolationPolicy(limits={"cpu_seconds": 1})  # type: ignore[arg-type]


def test_enter_sandbox_rejects_bad_slot_before_changing_anything(workdir: Path) -> None:
    with pytest.raises(UsageError, match="`slot` must be a non-negative integer; got -1"):
        enter_sandbox(DEFAULT, workdir, slot=-1)
    with pytest.raises(UsageError, match=r"`policy.base_uid \+ slot` must be below"):
        enter_sandbox(IsolationPolicy(base_uid=2**32 - 2), workdir, slot=1)
    with pytest.raises(UsageError, match="`workdir` must be an existing directory"):
        enter_sandbox(DEFAULT, workdir / "missing", slot=0)


def test_clean_environment_holds_only_the_fixed_variables(workdir: Path) -> None:
    env = clean_environment(workdir)
    assert env["HOME"] == str(workdir)
    assert env["PATH"] == "/usr/local/bin:/usr/bin:/bin"
    assert (workdir / ".tmp").is_dir() and env["TMPDIR"] == str(workdir / ".tmp")
    assert env["MPLBACKEND"] == "Agg" and env["OPENBLAS_NUM_THREADS"] == "1"
    assert set(env) == {
        "PATH", "HOME", "TMPDIR", "LANG", "LC_ALL", "MPLBACKEND", "MPLCONFIGDIR",
        "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
        "PYTHONDONTWRITEBYTECODE", "PYTHONHASHSEED",
    }


def test_readable_paths_leave_out_the_repository_and_install_records() -> None:
    paths = readable_paths([REPO])
    assert paths, "nothing would be readable"
    for path in paths:
        assert not path.is_relative_to(REPO), path
        assert not path.name.startswith("__editable__"), path
        assert not (path.name.startswith("numgrade") and path.name.endswith(".dist-info")), path
        assert path != Path("/etc/shadow")
    assert any(Path(sys.base_prefix).resolve() in [p, *p.parents] for p in paths)


def test_owners_of_the_hidden_packages_are_those_importlib_metadata_names() -> None:
    """The cheap lookup of who installs a package answers as packages_distributions()."""
    owners = importlib.metadata.packages_distributions()

    def expected(packages: Sequence[str]) -> set[str]:
        return {readable._normalise(d) for p in packages for d in owners.get(p, []) if d}

    # PathFinder, not importlib.util.find_spec: the latter asks every finder on
    # sys.meta_path, and setuptools' distutils shim, asked about "pip", switches itself
    # off for the rest of the process; nbgrader's import of setuptools then failed in
    # every later test of the same pytest run.
    importable = sorted(name for name in owners if name.isidentifier()
                        and importlib.machinery.PathFinder.find_spec(name) is not None)
    assert {"autograder", "numpy", "pytest"} <= set(importable)
    for package in [*readable.HIDDEN_PACKAGES, "numpy", "scipy", "IPython", "pytest", "_pytest",
                    "matplotlib", "mpl_toolkits", "nbformat", "six", "not_installed_at_all"]:
        assert readable._distribution_names([package]) == expected([package]), package
    assert readable._distribution_names(importable) == expected(importable)
    assert readable._distribution_names(readable.HIDDEN_PACKAGES) >= {"numgrade"}


def test_path_containment_by_components_is_pathlibs() -> None:
    """``_within`` and ``_outermost`` compare components; the answers are pathlib's."""
    paths = [Path(p) for p in ("/", "/a", "/a/b", "/a/bc", "/a/b/c", "/ab", "/a/b/c/d",
                                "/x/a/b", "/a/b/c.d")]
    for path in paths:
        for root in paths:
            assert readable._within(path, root) == (path == root or root in path.parents), \
                (path, root)
    assert readable._outermost([*paths[1:], Path("/a/b"), Path("/x/a/b")]) == [
        Path("/a"), Path("/ab"), Path("/x/a/b")]
    assert readable._outermost(paths) == [Path("/")]


def test_probe_support_is_cached_and_consistent() -> None:
    support = probe_support()
    assert probe_support() is support
    assert support.is_root == (os.geteuid() == 0)
    unavailable = any("Landlock is not available" in note for note in support.notes)
    assert unavailable == (support.landlock_abi == 0)


# ----------------------------------------------------------------------- files


def test_exclusions_outside_every_readable_root_change_nothing(tmp_path: Path) -> None:
    """A batch's submissions each exclude their own folder (outside every readable root):
    the readable paths are the same, so one shared ruleset serves them all; an excluded
    path inside a root changes the paths, and the ruleset is not reused for it."""
    first, second = tmp_path / "s0001" / "hull", tmp_path / "s0002" / "hull"
    inside = Path(readable._site_packages_dirs()[0]).resolve() / "numpy"
    assert not any(readable._within(tmp_path.resolve(), root) for root in readable._roots(()))
    assert readable_paths([REPO, first]) == readable_paths([REPO, second]) \
        == list(readable._readable_paths_cached((str(REPO), str(second)), ()))  # in full
    assert readable_paths([REPO, inside]) != readable_paths([REPO])
    assert readable._readable_paths_cached((str(REPO), str(inside)), ()) \
        == tuple(readable_paths([REPO, inside]))
    assert readable.holes_that_matter([REPO, first]) == readable.holes_that_matter([REPO, second])
    require_landlock(1, "a shared ruleset")
    root = tmp_path / "work"
    ruleset = shared_landlock(DEFAULT, root, [REPO, first])
    try:
        assert ruleset.serves(DEFAULT, root / "submission-x", [second, REPO])
        assert not ruleset.serves(DEFAULT, root / "submission-x", [REPO, inside])
    finally:
        ruleset.close()


@pytest.mark.parametrize("shared", [False, True], ids=["own-ruleset", "shared-ruleset"])
def test_write_outside_workdir_fails(tmp_path: Path, workdir: Path, shared: bool) -> None:
    require_landlock(1, "confining writes")
    open_dir = tmp_path / "world-writable"  # only Landlock stands in the way here
    open_dir.mkdir(mode=0o777)
    open_dir.chmod(0o777)
    target = open_dir / "escaped.txt"
    outcome = run_sandboxed(lambda: target.write_text("x"), workdir, shared=shared)
    assert outcome.error["error"] == "PermissionError"
    assert not target.exists()


def test_shared_ruleset_lets_a_child_change_nothing_beside_its_workdir(tmp_path: Path) -> None:
    """The warm parent's ruleset allows the whole work root; each child's own layer
    narrows writing to its working directory, as the fallback of one ruleset does."""
    require_landlock(1, "confining writes")
    root = tmp_path / "work-root"
    root.mkdir(mode=0o777)
    root.chmod(0o777)
    mine, left = root / "submission-a", root / "left-behind"
    mine.mkdir()
    ruleset = shared_landlock(DEFAULT, root, [])  # built while the root holds one folder
    left.mkdir(mode=0o777)  # a folder the grader would have removed, here on purpose
    left.chmod(0o777)
    (left / "old.txt").write_text("kept")

    def action() -> dict[str, str]:
        return {
            "beside": _try(lambda: (root / "planted.txt").write_text("x")),
            "sibling": _try(lambda: (left / "new.txt").write_text("x")),
            "remove": _try(lambda: (left / "old.txt").unlink()),
            "own": _try(lambda: Path("mine.txt").write_text("x")),
        }

    outcome = run_sandboxed(action, mine, slot=2, ruleset=ruleset)
    assert outcome.value["beside"] == outcome.value["sibling"] == "PermissionError"
    assert outcome.value["remove"] == "PermissionError"
    assert outcome.value["own"] != "PermissionError"
    assert not (root / "planted.txt").exists() and not (left / "new.txt").exists()
    assert (left / "old.txt").read_text() == "kept"
    assert any(note.startswith("landlock: ABI") for note in outcome.report["notes"])


def test_shared_ruleset_for_another_work_root_is_not_used(tmp_path: Path, workdir: Path) -> None:
    """A child whose working directory is not in the ruleset's work root builds its own."""
    require_landlock(1, "confining writes")
    ruleset = shared_landlock(DEFAULT, tmp_path / "elsewhere", [])
    assert not ruleset.serves(DEFAULT, workdir, [])
    assert not ruleset.serves(IsolationPolicy(allowed_read=(str(tmp_path),)),
                              tmp_path / "elsewhere" / "x", [])
    assert ruleset.serves(DEFAULT, tmp_path / "elsewhere" / "x", [])
    ruleset.close()


@pytest.mark.parametrize("shared", [False, True], ids=["own-ruleset", "shared-ruleset"])
def test_write_inside_workdir_works(workdir: Path, shared: bool) -> None:
    def action() -> list[str]:
        import tempfile

        Path("sub").mkdir()
        Path("sub/a.txt").write_text("answer")
        Path("sub/a.txt").rename("b.txt")
        with tempfile.NamedTemporaryFile() as handle:  # in $TMPDIR, despite the parent's cache
            handle.write(b"scratch")
        return sorted(os.listdir(".")) + [Path("b.txt").read_text()]

    outcome = run_sandboxed(action, workdir, slot=1, shared=shared)
    # The child's files live on its own tmpfs (the disk quota): checked from inside.
    assert "b.txt" in outcome.value
    assert outcome.value[-1] == "answer"
    assert any(note.startswith("landlock: ABI") for note in outcome.report["notes"]) or (
        probe_support().landlock_abi == 0
    )
    layers = [n for n in outcome.report["notes"] if n.startswith("landlock write layer: ABI")]
    assert len(layers) == (1 if shared and probe_support().landlock_abi > 0 else 0)


@pytest.mark.parametrize("shared", [False, True], ids=["own-ruleset", "shared-ruleset"])
def test_excluded_tree_inside_an_allowed_root_is_unreadable(tmp_path: Path, workdir: Path,
                                                           shared: bool) -> None:
    require_landlock(1, "confining reads")
    allowed = tmp_path / "allowed"
    repo = allowed / "repo"
    (repo / "checks").mkdir(parents=True)
    (repo / "checks" / "hidden.py").write_text("SECRET = 1\n")
    (allowed / "data.txt").write_text("public\n")
    policy = IsolationPolicy(allowed_read=(str(allowed),))

    def action() -> dict[str, str]:
        return {
            "public": (allowed / "data.txt").read_text(),
            "hidden": _try(lambda: (repo / "checks" / "hidden.py").read_text()),
            "listing": _try(lambda: os.listdir(repo)),
        }

    value = run_sandboxed(action, workdir, policy=policy, exclude=[repo], shared=shared).value
    assert value["public"] == "public\n"
    assert value["hidden"] == value["listing"] == "PermissionError"


@pytest.mark.parametrize("shared", [False, True], ids=["own-ruleset", "shared-ruleset"])
def test_repository_and_reference_package_are_unreadable(workdir: Path, shared: bool) -> None:
    require_landlock(1, "confining reads")
    design = REPO / "docs" / "design.md"
    source = REPO / "reference" / "_geometry.py"
    assert design.is_file() and source.is_file()
    preloaded = "reference._geometry" in sys.modules  # then the import cannot fail

    def action() -> dict[str, str]:
        return {
            "design": _try(design.read_text),
            "source": _try(source.read_text),
            "import": _try(lambda: __import__("reference._geometry")),
        }

    value = run_sandboxed(action, workdir, exclude=[REPO], shared=shared).value
    # FileNotFoundError where the repository is covered by an empty mount (see below)
    assert value["design"] == value["source"] in ("PermissionError", "FileNotFoundError")
    if not preloaded:
        assert value["import"] in ("PermissionError", "ModuleNotFoundError", "ImportError")


def test_excluded_folders_are_covered_so_not_even_their_names_show(tmp_path: Path,
                                                                    workdir: Path) -> None:
    """Landlock refuses reading a file but not ``stat``: an empty mount hides names and sizes."""
    support = probe_support()
    if not (support.is_root or support.user_namespaces):
        pytest.skip("no mount namespace for this user: excluded folders are unreadable "
                    "(Landlock) but their names can be looked up")
    hidden = tmp_path / "assignment" / "checks" / "hidden" / "test_secret.py"
    hidden.parent.mkdir(parents=True)
    hidden.write_text("ANSWER = 42\n")
    assert coverable_folders([tmp_path / "assignment"], workdir, DEFAULT) == (
        (tmp_path / "assignment").resolve(),)

    def action() -> dict[str, object]:
        return {"stat": _try(lambda: os.stat(hidden)), "exists": hidden.exists(),
                "parent": _try(lambda: os.stat(hidden.parent))}

    outcome = run_sandboxed(action, workdir, exclude=[tmp_path / "assignment"])
    assert outcome.value == {"stat": "FileNotFoundError", "exists": False,
                             "parent": "FileNotFoundError"}
    assert any("covered by empty mounts: 1" in n for n in outcome.report["notes"])
    assert hidden.read_text() == "ANSWER = 42\n", "the grader's own view is unchanged"


def test_only_folders_without_anything_the_child_needs_are_covered(tmp_path: Path,
                                                                   workdir: Path) -> None:
    """Not a folder holding the Python install (a venv in the repository), the working
    directory, or a folder inside an allowed root (a forbidden library in site-packages)."""
    stdlib = Path(json.__file__).resolve().parent.parent
    holding_python = stdlib.parent  # .../lib: holds the standard library
    inside_root = Path(json.__file__).resolve().parent  # like a forbidden library's folder
    checks = tmp_path / "checks"
    checks.mkdir()
    (checks / "inner").mkdir()
    policy = IsolationPolicy()
    got = coverable_folders([holding_python, inside_root, tmp_path, checks, checks / "inner",
                             tmp_path / "missing"], workdir, policy)
    assert got == (checks.resolve(),)


def _try(action: Callable[[], object]) -> str:
    """'ok' or the name of the exception ``action`` raised."""
    try:
        action()
    except Exception as exc:
        return type(exc).__name__
    return "ok"


def test_imports_work_after_the_sandbox(workdir: Path) -> None:
    modules = ["json", "decimal", "wave", "xml.dom.minidom", "scipy.linalg"]

    def action() -> dict[str, Any]:
        import importlib
        import importlib.util

        fresh = [name for name in modules if name not in sys.modules]
        for name in modules:
            spec = importlib.util.find_spec(name)
            spec.loader.get_data(spec.origin)  # read the file even if already imported
            importlib.import_module(name)
        import numpy as np
        import scipy.linalg

        return {"fresh": fresh, "det": float(scipy.linalg.det(np.eye(3)))}

    value = run_sandboxed(action, workdir, exclude=[REPO]).value
    assert value["det"] == 1.0
    assert "wave" in value["fresh"]


def test_already_open_socket_keeps_working(workdir: Path) -> None:
    parent_end, child_end = socket.socketpair()
    with parent_end, child_end:
        outcome = run_sandboxed(lambda: child_end.sendall(b"still here"), workdir)
        assert outcome.value is None
        assert parent_end.recv(100) == b"still here"


# --------------------------------------------------------------------- network


@pytest.mark.parametrize("policy", [DEFAULT, LANDLOCK_ONLY, NAMESPACE_ONLY],
                         ids=["default", "landlock-only", "namespace-only"])
def test_tcp_connect_to_loopback_listener_fails(policy: IsolationPolicy, workdir: Path) -> None:
    require_policy(policy)
    with socket.create_server(("127.0.0.1", 0)) as listener:
        address = listener.getsockname()

        def action() -> None:
            with socket.create_connection(address, timeout=2):
                pass

        outcome = run_sandboxed(action, workdir, policy=policy, slot=2)
        assert outcome.error["error"] in ("PermissionError", "OSError", "TimeoutError")
        listener.setblocking(False)
        with pytest.raises(BlockingIOError):
            listener.accept()


NETNS_CODE = "import os\ndef netns():\n    return os.readlink('/proc/self/ns/net')\n"
NETNS_CHECK = ("import os\n"
               "def test_netns(student):\n"
               "    with open(os.environ['NETNS_RECORD'], 'a') as record:\n"
               "        record.write(student.netns() + '\\n')\n")


def test_a_slots_children_share_one_empty_network_namespace_made_once(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """As root the warm parent makes the empty namespace once (``prepare_network``); each
    child is born in it, and none is in the grader's."""
    require_root("moving the warm parent into a network namespace")
    from autograder.engine.assignment import load_assignment
    from autograder.engine.grader import Grader
    from tests.support.assignments import submission, write_double

    record = tmp_path / "netns.txt"
    monkeypatch.setenv("NETNS_RECORD", str(record))
    folder = write_double(tmp_path, "netns", {"test_netns.py": NETNS_CHECK})
    with Grader(load_assignment(folder)) as grader:
        for k in range(2):
            assert grader.grade(submission(tmp_path / "in", f"s{k}", NETNS_CODE)).score == 1.0
        assert grader._slot.warm_parent is not None
        parent = os.readlink(f"/proc/{grader._slot.warm_parent}/ns/net")
    seen = record.read_text().split()
    assert seen == [parent, parent]
    assert parent != os.readlink("/proc/self/ns/net")


@pytest.mark.parametrize("policy", [DEFAULT, LANDLOCK_ONLY], ids=["default", "landlock-only"])
def test_tcp_bind_fails(policy: IsolationPolicy, workdir: Path) -> None:
    require_landlock(4, "blocking TCP bind")
    require_policy(policy)

    def action() -> None:
        with socket.socket() as server:
            server.bind(("127.0.0.1", 0))

    outcome = run_sandboxed(action, workdir, policy=policy, slot=2)
    assert outcome.error["error"] == "PermissionError"


# --------------------------------------------------------------------- signals


@pytest.mark.parametrize("policy, refusal", [
    (DEFAULT, "ProcessLookupError"),  # in its PID namespace, no process has the grader's pid
    (replace(LANDLOCK_ONLY, pid_namespace=False), "PermissionError"),  # Landlock's scope
], ids=["default", "landlock-only"])
def test_cannot_signal_the_grader(
    policy: IsolationPolicy, refusal: str, workdir: Path, grader_terms: list[int]
) -> None:
    require_policy(policy)
    grader = os.getpid()
    outcome = run_sandboxed(lambda: os.kill(grader, signal.SIGTERM), workdir, policy=policy)
    assert outcome.error["error"] == refusal
    time.sleep(0.05)
    assert grader_terms == []


def test_a_child_forked_as_the_warm_parent_does_is_process_1_of_its_own_namespace(
        workdir: Path, grader_terms: list[int]) -> None:
    """As root the warm parent makes the child's PID namespace before the fork (no relay):
    the child is process 1 and sees no other process, cannot signal the grader, and the
    parent's next children are born in its own namespace again, so forking goes on."""
    require_policy(DEFAULT)
    own = os.readlink("/proc/self/ns/pid")
    grader = os.getpid()

    def look() -> list[Any]:
        try:
            os.kill(grader, signal.SIGTERM)
        except ProcessLookupError:
            refused = True
        else:
            refused = False
        return [os.getpid(), sorted(p for p in os.listdir("/proc") if p.isdigit()), refused]

    for _ in range(3):  # a later fork would fail if the parent stayed in the last namespace
        outcome = run_sandboxed(look, workdir, fork=lambda: fork_child(DEFAULT))
        assert outcome.value == [1, ["1"], True]
        assert any(n.startswith("PID namespace:") for n in outcome.report["notes"])
        assert os.readlink("/proc/self/ns/pid_for_children") == own
    time.sleep(0.05)
    assert grader_terms == []


# ---------------------------------------------------------------------- limits


def test_fork_bomb_stops_at_the_process_limit(workdir: Path) -> None:
    policy = IsolationPolicy(limits=Limits(processes=8))

    def action() -> dict[str, Any]:
        children: list[int] = []
        failure = None
        for _ in range(64):
            try:
                pid = os.fork()
            except OSError as exc:
                failure = exc.errno
                break
            if pid == 0:
                try:
                    time.sleep(CHILD_DEADLINE)
                finally:
                    os._exit(0)
            children.append(pid)
        for pid in children:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        return {"forked": len(children), "errno": failure}

    value = run_sandboxed(action, workdir, policy=policy, slot=3).value
    assert value["errno"] == errno.EAGAIN
    assert value["forked"] < 8


def test_huge_allocation_raises_memory_error(workdir: Path) -> None:
    outcome = run_sandboxed(lambda: len(bytearray(12 * 2**30)), workdir)
    assert outcome.error["error"] == "MemoryError"


def test_writing_past_the_file_size_limit_fails(workdir: Path) -> None:
    limit = 2**20
    policy = IsolationPolicy(limits=Limits(file_size_bytes=limit))

    def action() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of death
        try:
            with open("big.bin", "wb") as handle:
                handle.write(b"\0" * (2 * limit))
        except OSError as exc:  # the file lives on the child's tmpfs: measured here
            return [exc.errno, os.path.getsize("big.bin")]
        return None

    errno_, size = run_sandboxed(action, workdir, policy=policy).value
    assert errno_ == errno.EFBIG
    assert size <= limit


def test_cpu_limit_kills_a_busy_loop(workdir: Path) -> None:
    policy = IsolationPolicy(limits=Limits(cpu_seconds=1))

    def action() -> None:
        while True:
            pass

    # One CPU second can take far longer on a busy machine: the deadline only catches a
    # limit that never fires.
    outcome = run_sandboxed(action, workdir, policy=policy, deadline=300)
    assert not outcome.timed_out, "the CPU limit did not stop the loop"
    assert outcome.signal in (signal.SIGXCPU, signal.SIGKILL)


# ------------------------------------------------------------- environment, user


def test_environment_holds_no_secret(workdir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SECRET_TOKEN", SECRET)

    def action() -> dict[str, Any]:
        proc = Path("/proc/self/environ").read_text("latin-1")
        return {"environ": dict(os.environ), "proc": proc}

    value = run_sandboxed(action, workdir).value
    assert "SECRET_TOKEN" not in value["environ"]
    assert set(value["environ"]) == set(clean_environment(workdir))
    assert SECRET not in value["proc"]


def test_grader_environment_is_unreadable_through_proc(workdir: Path) -> None:
    # Only with the user switch: Landlock (ABI 7, Linux 6.18) denies ptrace attach
    # and /proc/<pid>/mem but not PTRACE_MODE_READ, so a child that keeps the
    # grader's uid can read /proc/<grader>/environ.
    require_policy(DEFAULT)
    environ = Path(f"/proc/{os.getpid()}/environ")
    outcome = run_sandboxed(lambda: environ.read_bytes().hex(), workdir)
    assert outcome.error["error"] == "FileNotFoundError"  # not in the child's PID namespace
    outcome = run_sandboxed(lambda: environ.read_bytes().hex(), workdir,
                            policy=replace(DEFAULT, pid_namespace=False))
    assert outcome.error["error"] == "PermissionError"  # the user switch


def test_inherited_environment_block_is_wiped(workdir: Path) -> None:
    """A worker started with a secret must not show it in /proc/self/environ."""
    script = textwrap.dedent(f"""
        import json, sys
        from pathlib import Path
        from autograder.sandbox.confine import enter_sandbox, fork_child
        from autograder.sandbox.policy import IsolationPolicy
        proc = Path("/proc/self/environ")
        before = "{SECRET}" in proc.read_text("latin-1")
        enter_sandbox(IsolationPolicy(), Path({str(workdir)!r}), slot={SLOTS[4]})
        after = "{SECRET}" in proc.read_text("latin-1")
        sys.stdout.write(json.dumps([before, after]))
    """)
    env = {**os.environ, "SECRET_TOKEN": SECRET, "PYTHONPATH": str(REPO)}
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                            text=True, timeout=CHILD_DEADLINE, start_new_session=True)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == [True, False]


def test_child_runs_as_the_slot_user(workdir: Path) -> None:
    require_root("switching to the slot's user")
    policy = IsolationPolicy(base_uid=61000)

    def action() -> dict[str, Any]:
        lines = Path("/proc/self/status").read_text().splitlines()
        status = dict(line.split(":\t", 1) for line in lines)
        return {"ids": [os.getuid(), os.geteuid(), os.getgid(), os.getegid()],
                "groups": os.getgroups(), "workdir_uid": os.stat(".").st_uid,
                "caps": [int(status[key], 16) for key in ("CapEff", "CapPrm", "CapBnd", "CapInh")]}

    value = run_sandboxed(action, workdir, policy=policy, slot=5).value
    assert value["ids"] == [61000 + SLOTS[5]] * 4
    assert value["groups"] == []
    dac_read_search = 1 << 2
    assert value["caps"] == [dac_read_search, dac_read_search, dac_read_search, 0]
    assert value["workdir_uid"] == 61000 + SLOTS[5]
