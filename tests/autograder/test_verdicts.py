"""Verdicts are functions of the code alone: load, comments, interruptions, edits, rules.

Each test grades real notebooks through the real engine (``autograder`` in a
subprocess, or a :class:`Grader` in this process) and asserts the one thing a
user would otherwise discover as a wrong grade.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import nbformat
import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader, GradingOptions, engine_digest, submission_key
from autograder.engine.slot import GradingSlot
from autograder.engine.student_process import StudentProcess
from autograder.errors import EngineError
from autograder.sandbox.policy import IsolationPolicy
from tests.support.terminal import with_ctrl_c

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
SOLUTION = HULL / "examples" / "solution.ipynb"

pytestmark = pytest.mark.slow


def cli(*args: str, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "autograder", *args, "--no-progress"],
                          capture_output=True, text=True, timeout=timeout)


def results(folder: Path) -> dict[str, dict]:
    return {p.parent.name: json.loads(p.read_text()) for p in folder.glob("*/results.json")}


def per_check(result: dict) -> dict[str, float]:
    return {t["name"]: t["score"] for t in result["tests"]}


def with_cell(source: Path, code: str, target: Path, *, first: bool = False) -> Path:
    book = nbformat.read(source, as_version=4)
    cell = nbformat.v4.new_code_cell(code)
    book.cells.insert(0, cell) if first else book.cells.append(cell)
    target.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(book, target)
    return target


def _spin(stop: float) -> None:
    while time.monotonic() < stop:
        pass


# -- time limits are CPU time ---------------------------------------------------

def test_scores_do_not_change_when_every_core_is_busy(tmp_path: Path) -> None:
    """The model solution graded on an idle machine and beside busy loops on every core."""
    idle = tmp_path / "idle"
    proc = cli("grade", "hull", str(SOLUTION), "--out", str(idle))
    assert proc.returncode == 0, proc.stderr
    stop = time.monotonic() + 900
    hogs = [multiprocessing.get_context("spawn").Process(target=_spin, args=(stop,))
            for _ in range((os.cpu_count() or 1) + 1)]
    for hog in hogs:
        hog.start()
    try:
        busy = tmp_path / "busy"
        proc = cli("grade", "hull", str(SOLUTION), "--out", str(busy), "--jobs", "2")
    finally:
        for hog in hogs:
            hog.kill()
    assert proc.returncode == 0, proc.stderr
    calm, loaded = results(idle)["solution"], results(busy)["solution"]
    assert per_check(calm) == per_check(loaded)
    assert calm["score"] == calm["max_score"]
    assert 0 < loaded["extra_data"]["cpu_seconds"] < 120


def session(tmp_path: Path, cells: list[str], **options: float) -> StudentProcess:
    slot = GradingSlot(slot=0)
    made = StudentProcess(slot=slot, cells=list(enumerate(cells)), data_files=[],
                          policy=IsolationPolicy(), notebook_timeout=options.get("notebook", 30.0),
                          exclude=[ROOT])
    made.start()
    return made


def test_sleeping_is_not_computing_and_computing_is_measured(tmp_path: Path) -> None:
    work = session(tmp_path, [
        "import time\ndef nap(s):\n    time.sleep(s)\n    return 1\n"
        "def spin(s):\n    end = time.process_time() + s\n    while time.process_time() < end: pass\n    return 2\n"])
    try:
        # Sleeping longer than the CPU limit is fine (the wall backstop is far away)...
        assert work.call("nap", [1.5], {}, timeout=1.0)[0] == 1
        # ...burning more CPU than the limit is not, however fast the machine is.
        with pytest.raises(Exception, match="CPU time"):
            work.call("spin", [3.0], {}, timeout=1.0)
        assert work.cpu_seconds >= 1.0
    finally:
        work.close()
        work.slot.shutdown()


def test_larger_inputs_are_not_run_after_a_time_out(tmp_path: Path) -> None:
    from autograder.errors import CallTimeout, NotRun

    work = session(tmp_path, ["def f(xs):\n    if len(xs) > 5:\n        while True: pass\n    return len(xs)\n"])
    try:
        work.current_check = "`f[large]`"
        with pytest.raises(CallTimeout):
            work.call("f", [list(range(10))], {}, timeout=0.5)
        with pytest.raises(NotRun, match=r"ran out of time on `f\[large\]`"):
            work.call("f", [list(range(20))], {}, timeout=0.5)
        assert work.call("f", [[1, 2]], {}, timeout=0.5)[0] == 2  # smaller inputs still run
    finally:
        work.close()
        work.slot.shutdown()


# -- unseen data come from the assignment and the student -------------------------

def test_comments_and_file_names_do_not_change_a_score(tmp_path: Path) -> None:
    folder = tmp_path / "submitted" / "alice" / "hull"
    with_cell(SOLUTION, "# a comment the student added\n", folder / "hull.ipynb", first=True)
    other = tmp_path / "again" / "alice" / "hull" / "my-final-version.ipynb"
    other.parent.mkdir(parents=True)
    shutil.copy(SOLUTION, other)
    assignment = load_assignment("hull")
    with Grader(assignment) as grader:
        first = grader.grade(folder / "hull.ipynb", id="alice")
        second = grader.grade(other, id="alice")
    assert first.seed == second.seed
    assert [(t.name, t.score) for t in first.tests] == [(t.name, t.score) for t in second.tests]


# -- complete or absent ---------------------------------------------------------

def test_an_interrupted_batch_stores_no_partial_result(tmp_path: Path) -> None:
    folder = tmp_path / "submitted"
    for name in "abcdef":
        target = folder / name / "hull" / "hull.ipynb"
        target.parent.mkdir(parents=True)
        shutil.copy(SOLUTION, target)
    out = tmp_path / "out"
    proc = subprocess.Popen(with_ctrl_c([sys.executable, "-m", "autograder", "grade", "hull",
                                         str(folder), "--out", str(out), "--jobs", "1",
                                         "--no-progress"]),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 600
    while not list(out.glob("*/results.json")) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err.decode()[-3000:]
    expected_checks = None
    for result in results(out).values():  # whatever was stored is complete
        expected_checks = expected_checks or len(result["tests"])
        assert result["extra_data"]["outcome"] == "graded"
        assert len(result["tests"]) == expected_checks
        assert result["score"] == result["max_score"]
    proc2 = cli("grade", "hull", str(folder), "--out", str(out), "--jobs", "1")
    assert proc2.returncode == 0, proc2.stderr
    final = results(out)
    assert set(final) == set("abcdef")
    assert all(r["score"] == r["max_score"] for r in final.values())


def test_the_key_changes_with_data_checks_engine_and_policy(tmp_path: Path) -> None:
    copy = tmp_path / "hull"
    shutil.copytree(HULL, copy, ignore=shutil.ignore_patterns("examples"))
    before = submission_key("0" * 64, load_assignment(copy), GradingOptions())
    data = next((copy / "data").iterdir())
    data.write_bytes(data.read_bytes() + b"\n")
    after_data = submission_key("0" * 64, load_assignment(copy), GradingOptions())
    assert after_data != before
    (copy / "checks" / "hidden" / "note.txt").write_text("changed")
    after_checks = submission_key("0" * 64, load_assignment(copy), GradingOptions())
    assert after_checks != after_data
    looser = GradingOptions(policy=IsolationPolicy(landlock=False))
    assert submission_key("0" * 64, load_assignment(copy), looser) != after_checks
    assert len(engine_digest()) == 64


# -- the engine's failures are errors, never a student's zero ---------------------

def test_an_incomplete_sandbox_is_an_engine_error(tmp_path: Path) -> None:
    import numpy

    slot = GradingSlot(slot=0)
    broken = StudentProcess(slot=slot, cells=[(0, "x = 1")], data_files=[],
                            policy=IsolationPolicy(), notebook_timeout=30,
                            exclude=[Path(numpy.__file__).parent])
    try:
        if not IsolationPolicy().landlock:
            pytest.skip("Landlock is off")
        from autograder.sandbox.support import probe_support
        if probe_support().landlock_abi == 0:
            pytest.skip("Landlock is not available on this kernel: no file rules to get wrong")
        with pytest.raises(EngineError, match="cannot read"):
            broken.start()
    finally:
        broken.close()
        slot.shutdown()


# -- locked cells are the instructor's --------------------------------------------

def test_a_rewritten_locked_cell_is_restored(tmp_path: Path) -> None:
    from autograder.engine.notebook import locked_sources

    locked = locked_sources(HULL / "hull.ipynb")
    if not locked:
        pytest.skip("the hull notebook has no locked read-only code cell")
    grade_id, original = next(iter(locked.items()))
    book = nbformat.read(SOLUTION, as_version=4)
    for cell in book.cells:
        if cell.get("metadata", {}).get("nbgrader", {}).get("grade_id") == grade_id:
            cell.source = original + "\n\ndef orientation(p, q, r):\n    return 1\n"
    target = tmp_path / "hull.ipynb"
    nbformat.write(book, target)
    with Grader(load_assignment("hull")) as grader:
        result = grader.grade(target, id="mallory")
    assert any("locked" in note and grade_id in note for note in result.notes)


# -- banned libraries are enforced on what runs -------------------------------------

DODGES = {
    "importlib": "    import importlib\n    mod = importlib.import_module('scipy.' + 'spatial')\n",
    "dunder": "    mod = __import__('scipy.' + 'spatial', fromlist=['x'])\n",
    "vars": "    import sys, scipy\n    mod = sys.modules.get('scipy.' + 'spatial') or vars(scipy)['spa' + 'tial']\n",
    "exec": "    import base64\n    ns = {}\n    exec(base64.b64decode(b'aW1wb3J0IHNjaXB5LnNwYXRpYWwgYXMgbQ=='), ns)\n    mod = ns['m']\n",
    "alias": "    import sys\n    mod = None\n    for m in list(sys.modules.values()):\n"
             "        for v in list(vars(m).values()) if m else []:\n"
             "            if getattr(v, '__name__', '') == 'ConvexHull':\n"
             "                mod = type('M', (), {'ConvexHull': v})\n",
    "gc": "    import gc\n    mod = next(o for o in gc.get_objects() if getattr(o, '__name__', '') == 'scipy.spatial')\n",
}


def test_no_spelling_reaches_a_forbidden_library(tmp_path: Path) -> None:
    folder = tmp_path / "in"
    for name, prelude in DODGES.items():
        code = ("import numpy as np\ndef convex_hull(points):\n" + prelude +
                "    return [int(i) for i in mod.ConvexHull(np.asarray(points, float)).vertices]\n")
        with_cell(SOLUTION, code, folder / f"{name}.ipynb")
    out = tmp_path / "out"
    proc = cli("grade", "hull", str(folder), "--out", str(out), "--public-only")
    assert proc.returncode == 0, proc.stderr
    for name, result in results(out).items():
        hull_checks = [t for t in result["tests"] if t["name"].startswith("convex_hull")]
        assert hull_checks and all(t["score"] == 0 for t in hull_checks), name


# -- no submission sees another ---------------------------------------------------

def test_started_from_the_course_folder_the_worker_reads_no_other_submission(tmp_path: Path) -> None:
    """``python -m autograder`` puts the current folder on the grader's path: not readable."""
    course = tmp_path / "course"
    bob = course / "submitted" / "bob" / "hull" / "hull.ipynb"
    bob.parent.mkdir(parents=True)
    shutil.copy(SOLUTION, bob)
    probe = (f"try:\n    open({str(bob)!r}).read(10)\n    print('READ-CLASSMATE')\n"
             "except OSError as exc:\n    print('DENIED', type(exc).__name__)\n")
    with_cell(SOLUTION, probe, course / "submitted" / "eve" / "hull" / "hull.ipynb")
    from autograder.sandbox.support import probe_support
    if probe_support().landlock_abi == 0:
        pytest.skip("Landlock is not available on this kernel: files are not confined")
    proc = subprocess.run([sys.executable, "-m", "autograder", "grade", "hull", "submitted",
                           "--out", "results", "--public-only", "--no-progress"],
                          cwd=course, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    stdout = results(course / "results")["eve"]["extra_data"]["stdout"]
    assert "DENIED" in stdout and "READ-CLASSMATE" not in stdout
