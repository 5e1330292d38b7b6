"""End to end: grade every problem notebook with the real CLI, and check nothing escaped.

The notebooks live in ``tests/files/problems/`` (written by
``tests/files/make_problems.py``), each with the outcome it must get in
``expected.toml``. One batch grades them all, in a subprocess, as a person would:
once as root and once as an ordinary user with Debian's Python in a venv of its own
(created by ``tests/support/envs.py``; skipped with the reason where that is not
possible). After each batch, nothing may have escaped: no listener (TCP and UDP on
loopback, UNIX pathname, datagram and abstract sockets) received anything, no System
V IPC object or keyring key of a submission is left, no submission process survives,
and no file was written outside the work directories.
"""

from __future__ import annotations

import json
import os
import pwd
import re
import select
import shutil
import socket
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import nbformat
import pytest

from tests.support import envs

ROOT = Path(__file__).resolve().parents[2]
PROBLEMS = ROOT / "tests" / "files" / "problems"
EXPECTED = tomllib.loads((PROBLEMS / "expected.toml").read_text())
HULL = ROOT / "assignments" / "hull"
SECRET = "s3cr3t-token-that-must-not-leak"
ESCAPE_FILES = [Path("/tmp/autograder-escaped"), Path.home() / "autograder-escaped",
                Path("/work/autograder-escaped"), Path("/autograder-escaped"),
                Path("/tmp/results.json")]
PORTS = range(47000, 47020)
#: where the problem notebooks try to reach a listener (see tests/files/make_problems.py)
UNIX_LISTENER = Path("/tmp/autograder-listener.sock")
ABSTRACT_LISTENER = "\0autograder-listener"
#: System V key and process name used by the ipc-* and hydra notebooks
IPC_KEY = 0x6E67_7261
HYDRA_NAME = "ag-hydra"
SLOT_UIDS = range(61000, 62000)
IDENTITIES = ["root", "user"] if os.geteuid() == 0 else ["self"]

pytestmark = pytest.mark.slow


class Listeners:
    """Listeners that record anything a submission sends: TCP and UDP on loopback,
    UNIX stream and datagram sockets on a file any user may connect to, and an
    abstract UNIX socket."""

    def __init__(self) -> None:
        self.sockets: list[socket.socket] = []
        self.accepted: list[str] = []
        for port in PORTS:
            for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
                self._add(socket.AF_INET, kind, ("127.0.0.1", port))
        for path, kind in ((UNIX_LISTENER, socket.SOCK_STREAM),
                           (Path(f"{UNIX_LISTENER}.dgram"), socket.SOCK_DGRAM)):
            path.unlink(missing_ok=True)
            if self._add(socket.AF_UNIX, kind, str(path)):
                path.chmod(0o777)
        self._add(socket.AF_UNIX, socket.SOCK_STREAM, ABSTRACT_LISTENER)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    def _add(self, family: int, kind: int, address: object) -> bool:
        sock = socket.socket(family, kind)
        if family == socket.AF_INET:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(address)
            if kind == socket.SOCK_STREAM:
                sock.listen()
        except OSError:
            sock.close()
            return False
        sock.setblocking(False)
        self.sockets.append(sock)
        return True

    def _accept(self) -> None:
        while not self._stop.is_set():
            readable, _, _ = select.select(self.sockets, [], [], 0.2)
            for sock in readable:
                try:
                    if sock.type == socket.SOCK_STREAM:
                        conn, _ = sock.accept()
                        conn.close()
                    else:
                        sock.recv(65536)
                except OSError:
                    continue
                self.accepted.append(repr(sock.getsockname()))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for sock in self.sockets:
            sock.close()
        for path in (UNIX_LISTENER, Path(f"{UNIX_LISTENER}.dgram")):
            path.unlink(missing_ok=True)


def sysv_keys() -> set[int]:
    """Keys of every System V object in the grader's IPC namespace."""
    keys = set()
    for kind in ("shm", "msg", "sem"):
        for line in Path(f"/proc/sysvipc/{kind}").read_text().splitlines()[1:]:
            keys.add(int(line.split()[0]))
    return keys


def key_users() -> dict[int, int]:
    """Keys held per user id, from /proc/key-users (all users when read as root)."""
    counts = {}
    for line in Path("/proc/key-users").read_text().splitlines():
        uid, rest = line.split(":", 1)
        counts[int(uid)] = int(rest.split()[1].split("/")[0])
    return counts


def processes_named(name: str) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if (entry / "comm").read_text().strip() == name:
                    found.append(int(entry.name))
            except OSError:
                continue
    return found


@pytest.fixture(scope="module")
def user_env(ordinary_user_venv: tuple[envs.Env, Path]) -> tuple[envs.Env, Path]:
    """The ordinary user's venv and copy of the repository (built once per session, in
    conftest.py)."""
    return ordinary_user_venv


def huge_outputs_notebook(folder: Path) -> Path:
    """A correct submission carrying ~50 MB of outputs (made here, not committed)."""
    book = nbformat.read(PROBLEMS / "solution.ipynb", as_version=4)
    blob = "x" * (1024 * 1024)
    cell = book.cells[-1]
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=blob) for _ in range(50)]
    path = folder / "huge-outputs.ipynb"
    nbformat.write(book, path)
    return path


@pytest.fixture(scope="module", params=IDENTITIES)
def batch(request: pytest.FixtureRequest,
          tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    identity = request.param
    env_user, source = request.getfixturevalue("user_env") if identity == "user" else (None, ROOT)
    hull, problems = source / "assignments" / "hull", source / "tests" / "files" / "problems"
    for path in ESCAPE_FILES:
        path.unlink(missing_ok=True)
    top = envs.shared_tempdir(f"numgrade-batch-{identity}-")
    request.addfinalizer(lambda: shutil.rmtree(top, ignore_errors=True))
    extra, out, tmp = top / "extra", top / "results", top / "tmp"
    for folder in (extra, out, tmp):
        folder.mkdir()
        if env_user is not None:
            shutil.chown(folder, env_user.user, env_user.user)
    huge = huge_outputs_notebook(extra)
    os.chmod(huge, 0o644)

    def grade(*paths: Path) -> subprocess.CompletedProcess[str]:
        args = ["-m", "autograder", "grade", str(hull), *map(str, paths), "--out", str(out),
                "--jobs", "2", "--timeout", "8", "--call-timeout", "4", "--no-progress"]
        # TMPDIR of its own: the work directories must all be gone afterwards.
        env = dict(os.environ, SECRET_TOKEN=SECRET, TMPDIR=str(tmp))
        if env_user is None:
            return subprocess.run([sys.executable, *args], capture_output=True, text=True,
                                  env=env, timeout=3600, cwd=extra)
        return env_user.run("python", *args, cwd=extra, timeout=3600,
                            env={"SECRET_TOKEN": SECRET, "TMPDIR": str(tmp)})

    keys_before, listeners = key_users(), Listeners()
    try:
        proc = grade(problems, huge)
    finally:
        listeners.close()
    return {"out": out, "proc": proc, "accepted": listeners.accepted, "identity": identity,
            "grade": grade, "tmp": tmp, "keys_before": keys_before, "problems": problems,
            "uid": None if env_user is None else pwd.getpwnam(env_user.user).pw_uid}


def load(batch: dict[str, object], name: str) -> dict[str, object]:
    out = batch["out"]
    assert isinstance(out, Path)
    path = out / name / "results.json"
    assert path.exists(), f"no results.json for {name}; grader said:\n{batch['proc']}"
    return json.loads(path.read_text())


def all_text(result: dict[str, object]) -> str:
    return json.dumps(result)


def test_batch_finishes_with_status_zero(batch: dict[str, object]) -> None:
    proc = batch["proc"]
    assert isinstance(proc, subprocess.CompletedProcess)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "Graded" in proc.stdout


def test_every_submission_has_a_row(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    rows = (out / "grades.csv").read_text().splitlines()
    ids = {row.split(",")[0] for row in rows[1:]}
    assert ids == set(EXPECTED) | {"huge-outputs"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_problem_notebook_gets_its_outcome(batch: dict[str, object], name: str) -> None:
    expected = EXPECTED[name]
    result = load(batch, name)
    fraction = result["score"] / result["max_score"] if result["max_score"] else 0.0
    band = {"0": (0.0, 0.0), "1": (1.0, 1.0), "partial": (0.01, 0.99)}[expected["score"]]
    assert band[0] - 1e-9 <= fraction <= band[1] + 1e-9, (
        f"{name}: score {result['score']}/{result['max_score']}; output: {result['output']}\n"
        + "\n".join(f"{t['name']}: {t['output'][:300]}" for t in result["tests"] if t["status"] != "passed"))
    if "outcome" in expected:
        assert result["extra_data"]["outcome"] == expected["outcome"], result["output"]
    for text in expected.get("contains", []):
        assert text in all_text(result), f"{name}: feedback lacks {text!r}"
    if "cell_errors" in expected:
        assert len(result["extra_data"]["cell_errors"]) == expected["cell_errors"]
    if "max_stdout" in expected:
        assert len(result["extra_data"]["stdout"]) <= expected["max_stdout"]


def test_huge_outputs_notebook_is_graded(batch: dict[str, object]) -> None:
    result = load(batch, "huge-outputs")
    assert result["score"] == result["max_score"] > 0


def test_no_file_escaped(batch: dict[str, object]) -> None:
    leaked = [str(p) for p in ESCAPE_FILES if p.exists()]
    out = batch["out"]
    assert isinstance(out, Path)
    forged = [p for p in out.rglob("results.json") if '"score": 100' in p.read_text()]
    assert not leaked and not forged


def test_no_connection_reached_a_listener(batch: dict[str, object]) -> None:
    # TCP and UDP on loopback, UNIX pathname (stream, datagram) and abstract sockets
    assert batch["accepted"] == []


def test_hidden_checks_never_appear_in_results(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    # Lines of code, not data: a failing check may rightly quote the input it used.
    hidden_lines = [line.strip() for f in (HULL / "checks" / "hidden").glob("*.py")
                    for line in f.read_text().splitlines()
                    if len(line.strip()) > 30 and re.search(r"[A-Za-z_]{4,}", line)]
    assert hidden_lines, "the hull assignment should have hidden checks"
    for path in out.rglob("results.json"):
        text = path.read_text()
        found = [line for line in hidden_lines if line in text]
        assert not found, f"{path.parent.name} leaked hidden check text: {found[:2]}"


def test_no_secret_in_results(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    for path in out.rglob("results.json"):
        assert SECRET not in path.read_text(), path


def test_no_student_process_survives(batch: dict[str, object]) -> None:
    # The hydra notebook re-forks itself in new sessions faster than a sweep of /proc.
    assert processes_named(HYDRA_NAME) == []
    if batch["identity"] != "root":
        return  # the ordinary user's own processes include unrelated ones: the name suffices
    out = batch["out"]
    assert isinstance(out, Path)
    uids = set()  # the users this batch's workers ran as, from the notes of each result
    for path in out.rglob("results.json"):
        for note in json.loads(path.read_text())["extra_data"]["notes"]:
            found = re.search(r"uid and gid (\d+)", note)
            if found:
                uids.add(int(found.group(1)))
    assert uids, "the workers should have run as dedicated users"
    survivors = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                status = (entry / "status").read_text()
            except OSError:
                continue
            uid = next(int(line.split()[1]) for line in status.splitlines() if line.startswith("Uid:"))
            if uid in uids:
                survivors.append(entry.name)
    assert survivors == []


def test_no_ipc_object_or_key_is_left(batch: dict[str, object]) -> None:
    assert IPC_KEY not in sysv_keys(), "a System V object of ipc-a-leave outlived it"
    before, after = batch["keys_before"], key_users()
    assert isinstance(before, dict)
    grew = {uid: n for uid, n in after.items()
            if (uid in SLOT_UIDS or uid == batch["uid"]) and n > before.get(uid, 0)}
    assert grew == {}, f"keyring keys left by submissions (uid: keys): {grew}"


def test_no_work_directory_is_left(batch: dict[str, object]) -> None:
    tmp = batch["tmp"]
    assert isinstance(tmp, Path)
    # Submissions' work directories, and the slots' own homes: a ``--jobs 2`` run's
    # pool processes close their graders when they exit. (The slot locks' folder,
    # ``autograder-slots-<uid>``, is meant to stay.)
    left = sorted(p.name for p in tmp.iterdir()
                  if p.name.startswith(("submission-", "autograder-slot-")))
    assert left == []


def test_nothing_was_taken_from_another_submission(batch: dict[str, object]) -> None:
    result = load(batch, "ipc-b-take")
    assert "took the solution" not in result["extra_data"]["stdout"]
    assert result["score"] == 0


def test_regrading_reuses_every_result(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    before = {p: p.read_text() for p in out.rglob("results.json")}
    grade = batch["grade"]
    assert callable(grade)
    proc = grade(batch["problems"])
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert f"reused {len(EXPECTED)}" in proc.stdout
    assert all(p.read_text() == text for p, text in before.items() if p.parent.name in EXPECTED)
