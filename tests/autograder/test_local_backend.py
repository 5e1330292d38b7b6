"""The local pool (``--jobs N``): this process is one slot, the pool's processes the others.

Whatever happens to a slot process or to the command (a slot process killed, Ctrl-C
on the whole process group), every submission ends with one whole result or none,
and no process or folder of the run is left behind.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import pytest

from autograder import api
from autograder.engine.slot import GradingSlot, slot_lock_dir
from autograder.sandbox.tempdirs import LOCK_NAME
from autograder.results.model import SubmissionResult
from autograder.runners import local
from tests.support.pool import pool_processes, slot_zero_waits
from tests.support.terminal import with_ctrl_c

ROOT = Path(__file__).resolve().parents[2]
SOLUTION = ROOT / "assignments" / "hull" / "examples" / "solution.ipynb"

pytestmark = pytest.mark.slow


def copies(folder: Path, count: int) -> Path:
    folder.mkdir(parents=True)
    for k in range(count):
        shutil.copy(SOLUTION, folder / f"student{k:02d}.ipynb")
    return folder


def test_a_killed_slot_process_costs_no_submission(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    submissions = copies(tmp_path / "in", 12)
    # A killed process cannot remove its slot's folder: it goes here, not to /tmp.
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr(tempfile, "tempdir", None)
    killed: list[int] = []
    pool_reported = threading.Event()

    def kill_the_pool(result: SubmissionResult) -> None:
        # Once, at the first result a pool process graded (reported from the pool's
        # feeder thread): the pool is ready then, and whatever its other process held
        # is graded again, by a new pool or by this process's slot.
        if not killed and threading.current_thread() is not threading.main_thread():
            for proc in pool_processes():
                proc.kill()
                killed.append(proc.pid)
            pool_reported.set()

    # This process's slot starts grading only once the pool has graded one file, so
    # however fast this slot is, the pool gets files to lose.
    monkeypatch.setattr(local, "grade_one", slot_zero_waits(pool_reported, local.grade_one))
    report = api.grade("hull", [submissions], out=tmp_path / "out", jobs=3, progress=False,
                       on_result=kill_the_pool)
    assert killed, "no pool process graded a file"
    assert sorted(r.id for r in report.results) == [f"student{k:02d}" for k in range(12)]
    assert {r.outcome for r in report.results} == {"graded"}
    assert all(r.score == r.max_score for r in report.results)
    stored = sorted(p.parent.name for p in (tmp_path / "out").glob("*/results.json"))
    assert stored == [r.id for r in report.results]


def test_a_pool_that_cannot_start_costs_no_submission(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # Seen once in CI: multiprocessing's resource tracker pipe was broken when the pool
    # was set up. This process's slot then grades every file, and says why.
    submissions = copies(tmp_path / "in", 3)

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise BrokenPipeError(32, "Broken pipe")

    for method in ("fork", "spawn"):  # the first pool is forked when it can be
        monkeypatch.setattr(multiprocessing.get_context(method), "Value", broken)
    report = api.grade("hull", [submissions], out=tmp_path / "out", jobs=2, progress=False)
    assert sorted(r.id for r in report.results) == ["student00", "student01", "student02"]
    assert all(r.outcome == "graded" and r.score == r.max_score for r in report.results)
    assert "could not start 1 more grading process(es) (BrokenPipeError" in capsys.readouterr().err


def test_ctrl_c_keeps_whole_results_and_leaves_nothing_behind(tmp_path: Path) -> None:
    submissions = copies(tmp_path / "in", 10)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    out = tmp_path / "out"
    grade = [sys.executable, "-m", "autograder", "grade", "hull", str(submissions),
             "--out", str(out), "--jobs", "2", "--no-progress"]
    proc = subprocess.Popen(with_ctrl_c(grade),  # even when this pytest ignores SIGINT
                            env={**os.environ, "TMPDIR": str(scratch)}, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while not list(out.glob("*/results.json")) and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 130, err[-3000:]
    assert "interrupted" in err
    for path in out.glob("*/results.json"):  # whatever was stored is whole
        result = json.loads(path.read_text())
        assert result["extra_data"]["outcome"] == "graded"
        assert result["score"] == result["max_score"]
    # The session's processes end with it (the warm parents on their parent's death).
    deadline = time.monotonic() + 60
    while _in_session(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _in_session(proc.pid) == []
    left = sorted(p.name for p in scratch.iterdir()
                  if p.name.startswith(("submission-", "autograder-slot-")))
    assert left == []


def _in_session(sid: int) -> list[str]:
    found = []
    for proc in psutil.process_iter():
        try:
            if os.getsid(proc.pid) == sid and proc.status() != psutil.STATUS_ZOMBIE:
                found.append(" ".join(proc.cmdline())[:200])
        except (OSError, psutil.Error):
            continue
    return found


# The pool's processes are forked from the batch's process once slot 0 collected the
# checks, and only while that process runs no other thread; this script notes which
# way each pool process started and which process collected the checks. Its patches
# are made at import, outside the ``__main__`` guard, so that a spawned process (which
# runs the script again as ``__mp_main__``) notes itself too.
_WATCHED_BATCH = '''
import os, sys, threading
from autograder.engine import grader
from autograder.runners import local

def note(word):
    with open(os.environ["NUMGRADE_TEST_LOG"], "a") as log:
        log.write(f"{word} {os.getpid()}\\n")

class Noted(grader.CheckSuite):
    def __init__(self, *args, **kwargs):
        note("collected")
        super().__init__(*args, **kwargs)

grader.CheckSuite = Noted
forked, spawned = local._init_forked_slot, local._init_slot

def init_forked(*args):
    note("forked")
    forked(*args)

def init_spawned(*args):
    note("spawned")
    spawned(*args)

local._init_forked_slot, local._init_slot = init_forked, init_spawned

if __name__ == "__main__":
    note("batch")
    if sys.argv[1] == "with-a-thread":
        threading.Thread(target=threading.Event().wait, daemon=True).start()
    from autograder.cli import main
    sys.exit(main(sys.argv[2:]))
'''


def _watched_batch(tmp_path: Path, books: Path, mode: str) -> tuple[dict[str, list[int]], dict]:
    script, log, out = tmp_path / "batch.py", tmp_path / f"{mode}.log", tmp_path / mode
    script.write_text(_WATCHED_BATCH)
    proc = subprocess.run([sys.executable, str(script), mode, "grade", "hull", str(books),
                           "--out", str(out), "--jobs", "2", "--no-progress"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=600,
                          env={**os.environ, "NUMGRADE_TEST_LOG": str(log),
                               "TMPDIR": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    noted: dict[str, list[int]] = {}
    for line in log.read_text().splitlines():
        word, pid = line.split()
        noted.setdefault(word, []).append(int(pid))
    scores = {p.parent.name: json.loads(p.read_text())["score"] for p in out.glob("*/results.json")}
    return noted, scores


def test_the_pool_is_forked_with_the_collected_checks_unless_a_thread_runs(tmp_path: Path) -> None:
    books = tmp_path / "in"
    books.mkdir()
    for k, example in enumerate(sorted(SOLUTION.parent.glob("*.ipynb"))[:4]):
        shutil.copy(example, books / f"s{k}-{example.name}")
    noted, scores = _watched_batch(tmp_path, books, "alone")
    batch = noted["batch"]
    # Forked: the pool process holds the batch's collected checks and collects nothing.
    assert len(noted["forked"]) == 1 and "spawned" not in noted
    assert noted["collected"] == batch
    # A process with a thread of its own does not fork: the pool process is spawned, and
    # imports and collects for itself. The grades are the same either way.
    noted, spawned_scores = _watched_batch(tmp_path, books, "with-a-thread")
    assert len(noted["spawned"]) == 1 and "forked" not in noted
    assert sorted(noted["collected"]) == sorted(noted["batch"] + noted["spawned"])
    assert len(scores) == 4 and spawned_scores == scores


def test_a_forked_copy_of_a_slot_lets_go_of_it_and_leaves_its_worker(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)
    slot = GradingSlot()
    try:
        slot.start()
        warm = slot.warm_parent
        read, write = os.pipe()
        pid = os.fork()
        if pid == 0:  # what a forked pool process does with slot 0's copy (Grader.sibling)
            try:
                slot.disown()
                os.write(write, b"k")
                time.sleep(600)
            finally:
                os._exit(0)
        os.close(write)
        try:
            assert os.read(read, 1) == b"k"
            # The copy touched neither the owner's warm parent nor its folder...
            assert warm is not None and slot.warm_parent == warm
            assert slot.work_root.is_dir()
            home = slot.work_root.parent
            control = slot._control  # internal: the warm parent's socket
            assert control is not None
            held = {str(slot_lock_dir() / f"{slot.slot}.lock"), str(home / LOCK_NAME),
                    f"socket:[{os.fstat(control.fileno()).st_ino}]"}
            # ...and holds none of the slot's descriptors: not its lock nor its folder's
            # (each an flock, the open file's, which the copy would otherwise hold as
            # long as it lives), nor the warm parent's socket. Read from the copy's own
            # descriptor table: another grader on this machine may claim a free slot.
            copy_holds = {os.readlink(f"/proc/{pid}/fd/{fd}")
                          for fd in os.listdir(f"/proc/{pid}/fd")}
            assert not held & copy_holds
            slot.shutdown()
            assert not home.exists()
        finally:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(read)
    finally:
        slot.shutdown()
