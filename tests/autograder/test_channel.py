"""End to end: the channel between the grader and the worker holds against the student.

Each problem notebook here attacks the channel (issue 24): one floods it with frames
and never reads, one forges the sandbox's ``sandbox-broken`` report, one forks a
helper whose ``setsid()`` is refused and which unwinds back into the worker's loop,
and one has far too many cells. Each is graded in a batch with honest notebooks
before and after it, with the real CLI in a subprocess, as root and as an ordinary
user; the batch must finish (a generous timeout fails the test instead of hanging),
every file must get a result, the attacker's outcome must be the student's (never
``error``) and the honest files must keep their full score.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import nbformat
import pytest

from tests.files.make_problems import SOLUTION, nb
from tests.support import envs

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
IDENTITIES = ["root", "user"] if os.geteuid() == 0 else ["self"]
#: a batch that takes longer than this hangs (the attacks used to hang forever)
BATCH_TIMEOUT = 1500

pytestmark = pytest.mark.slow

#: finds the worker's end of the channel: every socket among this process's descriptors
SOCKETS = (
    "import json, os, struct, time\n"
    "def channel_fds():\n"
    "    found = []\n"
    "    for fd in map(int, os.listdir('/proc/self/fd')):\n"
    "        try:\n"
    "            if os.readlink(f'/proc/self/fd/{fd}').startswith('socket:'):\n"
    "                found.append(fd)\n"
    "        except OSError:\n"
    "            pass\n"
    "    return found\n"
    "def frame(value):\n"
    "    header = json.dumps({'v': value, 'bufs': []}).encode()\n"
    "    return struct.pack('>I', len(header)) + header\n")

#: 5,000 unsolicited callback requests written when the hull is asked for, never reading
FLOOD = SOCKETS + (
    "_real_hull = convex_hull\n"
    "def convex_hull(points):\n"
    "    blob = frame({'op': 'callback', 'id': 'g1', 'args': [], 'kwargs': {}}) * 5000\n"
    "    for fd in channel_fds():\n"
    "        os.set_blocking(fd, True)\n"
    "        os.write(fd, blob)\n"
    "    while True:\n"
    "        time.sleep(1)\n")

#: the sandbox's own report, forged by a cell and again by a call
FORGED_BROKEN_CELL = SOCKETS + (
    "for fd in channel_fds():\n"
    "    os.write(fd, frame({'op': 'sandbox-broken', 'path': '/usr/lib/python3',"
    " 'error': 'Permission denied'}))\n"
    "time.sleep(2)\n")
FORGED_BROKEN_CALL = SOCKETS + (
    "_real_orientation = orientation\n"
    "def orientation(p, q, r):\n"
    "    for fd in channel_fds():\n"
    "        os.write(fd, frame({'op': 'sandbox-broken', 'path': '/usr/lib/python3',"
    " 'error': 'Permission denied'}))\n"
    "    time.sleep(2)\n"
    "    return _real_orientation(p, q, r)\n")

#: correct code with a forked helper that detaches with setsid(); where seccomp refuses
#: setsid, the helper unwinds (an exception) back into whatever called the function
FORKING = (
    "import os\n"
    "def _detached_helper():\n"
    "    pid = os.fork()\n"
    "    if pid == 0:\n"
    "        os.setsid()\n"
    "        os._exit(0)\n"
    "    os.waitpid(pid, 0)\n"
    "_jarvis = convex_hull\n"
    "def convex_hull(points):\n"
    "    _detached_helper()\n"
    "    return _jarvis(points)\n")
#: the same helper in a cell, and a helper that fails on purpose after the fork
FORKING_CELL = (
    "import os\n"
    "pid = os.fork()\n"
    "if pid == 0:\n"
    "    raise RuntimeError('the helper gave up')\n"
    "os.waitpid(pid, 0)\n")

TOO_MANY_CELLS = 340_000


def many_cells_notebook(path: Path, count: int) -> None:
    """A notebook of ``count`` one-line code cells, written as JSON (nbformat is slow here)."""
    book = nb(SOLUTION)
    data = json.loads(nbformat.writes(book))
    data["cells"] += [{"cell_type": "code", "id": f"c{i}", "metadata": {}, "outputs": [],
                       "execution_count": None, "source": "x = 1"} for i in range(count)]
    path.write_text(json.dumps(data))


def write_batch(folder: Path) -> dict[str, str]:
    """The batch's notebooks (honest ones around the attacks); returns name -> kind."""
    books = {
        "a-honest": nb(SOLUTION),
        "b-flood": nb(SOLUTION, FLOOD),
        "c-honest": nb(SOLUTION),
        "d-forged-broken-cell": nb(FORGED_BROKEN_CELL, SOLUTION),
        "e-forged-broken-call": nb(SOLUTION, FORGED_BROKEN_CALL),
        "f-forking": nb(SOLUTION, FORKING),
        "g-forking-cell": nb(FORKING_CELL, SOLUTION),
        "i-honest": nb(SOLUTION),
    }
    for name, book in books.items():
        nbformat.write(book, folder / f"{name}.ipynb")
    many_cells_notebook(folder / "h-many-cells.ipynb", TOO_MANY_CELLS)
    for path in folder.iterdir():
        os.chmod(path, 0o644)
    return {name: name for name in [*books, "h-many-cells"]}


@dataclass
class Launched:
    """One identity's batch, running in the background; its output goes to files."""

    proc: subprocess.Popen[bytes]
    out: Path
    names: dict[str, str]
    logs: Path
    started: float

    def wait(self) -> dict[str, object]:
        left = BATCH_TIMEOUT - (time.monotonic() - self.started)
        try:
            self.proc.wait(timeout=max(left, 0))
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            pytest.fail(f"the batch did not finish within {BATCH_TIMEOUT} s: the grader hangs")
        proc = subprocess.CompletedProcess(self.proc.args, self.proc.returncode,
                                           (self.logs / "stdout").read_text(),
                                           (self.logs / "stderr").read_text())
        return {"out": self.out, "proc": proc, "names": self.names}


def launch(identity: str, request: pytest.FixtureRequest) -> Launched:
    """Start ``identity``'s batch (the ordinary user's venv is built first, if need be)."""
    env_user, source = request.getfixturevalue("ordinary_user_venv") if identity == "user" else (None, ROOT)
    top = envs.shared_tempdir(f"numgrade-channel-{identity}-")
    request.addfinalizer(lambda: shutil.rmtree(top, ignore_errors=True))
    books, out, tmp, logs = top / "books", top / "results", top / "tmp", top / "logs"
    for folder in (books, out, tmp, logs):
        folder.mkdir()
        if env_user is not None:
            shutil.chown(folder, env_user.user, env_user.user)
    names = write_batch(books)
    args = ["-m", "autograder", "grade", str(source / "assignments" / "hull"), str(books),
            "--out", str(out), "--jobs", "1", "--timeout", "20", "--call-timeout", "4",
            "--no-progress"]
    if env_user is None:
        argv, env = [sys.executable, *args], dict(os.environ, TMPDIR=str(tmp))
    else:
        argv, env = env_user.command("python", *args), env_user.environment({"TMPDIR": str(tmp)})
    with (logs / "stdout").open("wb") as stdout, (logs / "stderr").open("wb") as stderr:
        proc = subprocess.Popen(argv, cwd=top, env=env, stdout=stdout, stderr=stderr)
    request.addfinalizer(lambda: proc.poll() is None and (proc.kill(), proc.wait()))
    return Launched(proc, out, names, logs, time.monotonic())


@pytest.fixture(scope="module")
def launched(request: pytest.FixtureRequest) -> dict[str, Launched]:
    """Every identity's batch, started at once: each grades on one slot (``--jobs 1``), so on
    two cores root's batch runs while the ordinary user's venv is built and their batch
    runs (they used to run one after the other). A root and an ordinary user's grader never
    share a slot (engine/slot.py). An identity that cannot start (its venv skipped or
    failed) is left out here; its own ``batch`` asks for the venv again and reports why."""
    started: dict[str, Launched] = {}
    for identity in IDENTITIES:
        try:
            started[identity] = launch(identity, request)
        except (Exception, pytest.skip.Exception):
            continue
    return started


@pytest.fixture(scope="module", params=IDENTITIES)
def batch(request: pytest.FixtureRequest, launched: dict[str, Launched]) -> dict[str, object]:
    identity = request.param
    if identity not in launched:
        return launch(identity, request).wait()  # raises the venv's skip or error here
    return launched[identity].wait()


def load(batch: dict[str, object], name: str) -> dict[str, object]:
    path = batch["out"] / name / "results.json"  # type: ignore[operator]
    assert path.exists(), f"no result for {name}; the grader said:\n{batch['proc']}"
    return json.loads(path.read_text())


def fraction(result: dict[str, object]) -> float:
    return result["score"] / result["max_score"] if result["max_score"] else 0.0  # type: ignore[operator]


def failures(result: dict[str, object]) -> str:
    return result["output"] + "\n" + "\n".join(  # type: ignore[operator]
        f"{t['name']}: {t['output'][:300]}" for t in result["tests"] if t["status"] != "passed")


def test_batch_finishes_with_a_result_for_every_file(batch: dict[str, object]) -> None:
    proc = batch["proc"]
    assert proc.returncode == 0, proc.stderr[-4000:]  # type: ignore[attr-defined]
    rows = (batch["out"] / "grades.csv").read_text().splitlines()  # type: ignore[operator]
    assert {row.split(",")[0] for row in rows[1:]} == set(batch["names"])  # type: ignore[arg-type]
    for name in batch["names"]:  # type: ignore[attr-defined]
        assert load(batch, name)["extra_data"]["outcome"] != "error", failures(load(batch, name))


@pytest.mark.parametrize("name", ["a-honest", "c-honest", "i-honest"])
def test_honest_files_keep_their_score(batch: dict[str, object], name: str) -> None:
    result = load(batch, name)
    assert fraction(result) == 1.0, failures(result)
    assert result["extra_data"]["outcome"] == "graded"


def test_flood_is_the_students_protocol_violation(batch: dict[str, object]) -> None:
    result = load(batch, "b-flood")
    assert "broke the grader's protocol" in json.dumps(result), failures(result)
    assert 0.0 < fraction(result) < 1.0, failures(result)  # orientation's checks still pass


def test_forged_sandbox_report_in_a_cell_is_not_believed(batch: dict[str, object]) -> None:
    result = load(batch, "d-forged-broken-cell")
    assert fraction(result) == 1.0, failures(result)  # the cell is skipped, the rest re-run
    assert result["extra_data"]["outcome"] == "crashed"
    assert "broke the grader's protocol" in result["output"]
    assert "sandbox is incomplete" not in json.dumps(result)


def test_forged_sandbox_report_in_a_call_is_not_believed(batch: dict[str, object]) -> None:
    result = load(batch, "e-forged-broken-call")
    assert "broke the grader's protocol" in json.dumps(result), failures(result)
    assert "sandbox is incomplete" not in json.dumps(result)
    assert fraction(result) < 1.0


@pytest.mark.parametrize("name", ["f-forking", "g-forking-cell"])
def test_code_that_forks_keeps_its_score(batch: dict[str, object], name: str) -> None:
    result = load(batch, name)
    assert fraction(result) == 1.0, failures(result)
    assert result["extra_data"]["outcome"] == "graded"


def test_too_many_cells_says_so_and_that_it_never_ran(batch: dict[str, object]) -> None:
    result = load(batch, "h-many-cells")
    assert result["extra_data"]["outcome"] == "ungradable"
    assert f"{TOO_MANY_CELLS + 1:,} code cells" in result["output"]
    assert "None of its code was run" in result["output"]
    assert "worker stopped" not in json.dumps(result)
