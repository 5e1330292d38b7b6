"""A batch's later slots run on copies of the first slot's warm parent (``--jobs N``).

The copy is forked by the first warm parent before its first submission and adopted
by the grader: it must be the grader's child and nobody else's (the first warm parent
reaps its children and counts their CPU time, and closing its slot kills its
descendants), die with the grader, be refused once the first warm parent served a
submission, and grade exactly as a warm parent started on its own. As root and as an
ordinary user (whose CPU clock reads the warm parent's reaped children).
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import pytest

from autograder import api
from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from autograder.engine.slot import GradingSlot
from autograder.runners import local
from autograder.sandbox.pidfd import pidfds_supported
from tests.support import envs
from tests.support.pool import pool_processes, slot_zero_waits

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
EXAMPLES = HULL / "examples"

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not sys.platform.startswith("linux") or not pidfds_supported(),
                       reason="warm parent copies need Linux pidfds (5.3+); without them "
                              "every slot starts its own warm parent"),
]


def _subreaper() -> int:
    was = ctypes.c_int(-1)
    ctypes.CDLL(None).prctl(37, ctypes.byref(was), 0, 0, 0)  # PR_GET_CHILD_SUBREAPER
    return was.value


def _gone_or_zombie(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def test_a_copy_is_the_graders_child_grades_alike_and_is_reaped(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    assignment = load_assignment(HULL)
    first, second = GradingSlot(), GradingSlot()
    subreaper_before = _subreaper()
    try:
        first.start()
        [(pid, control)] = first.warm_copies(1, forbid=assignment.rules.to_wire())
        assert _subreaper() == subreaper_before  # the grader adopts orphans only meanwhile
        assert psutil.Process(pid).ppid() == os.getpid()
        assert first.warm_parent is not None
        below_first = {p.pid for p in psutil.Process(first.warm_parent).children(recursive=True)}
        assert pid not in below_first
        assert second.adopt(pid, control)
        assert second.warm_parent == pid
        graders = [Grader(assignment, started_slot=slot) for slot in (first, second)]
        scores = []
        for grader in graders:
            graded = grader.grade(EXAMPLES / "wrong-clockwise.ipynb",
                                  out_dir=tmp_path / f"out{len(scores)}")
            scores.append((graded.score, graded.outcome, [t.status for t in graded.tests]))
            # Served a submission: no copy of it any more (the slots left start their own).
            assert first.warm_copies(1, forbid=assignment.rules.to_wire()) == []
        assert scores[0] == scores[1]
        assert scores[0][1] == "graded" and {"passed", "failed"} <= set(scores[0][2])
        graders[1].close()  # the slot that adopted the copy kills it; its zombie is ours
        assert _gone_or_zombie(pid)
        graders[0].close()
    finally:
        second.shutdown()
        first.shutdown()
    with pytest.raises(psutil.NoSuchProcess):
        psutil.Process(pid)  # reaped by the first slot's shutdown, no zombie left


_HOLDER = """
import sys, time
from autograder.engine.slot import GradingSlot
slot = GradingSlot()
slot.start()
copies = slot.warm_copies(2)
print(slot.warm_parent, *[pid for pid, _ in copies], flush=True)
time.sleep(600)
"""


def test_copies_die_with_their_grader(tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "TMPDIR": str(tmp_path)})
    try:
        assert proc.stdout is not None
        pids = [int(p) for p in proc.stdout.readline().split()]
        assert len(pids) == 3, "the holder made no copies"
        for pid in pids:
            assert psutil.Process(pid).ppid() == proc.pid
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 60
    while not all(_gone_or_zombie(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert all(_gone_or_zombie(p) for p in pids), "a warm parent outlived its grader"


def test_pool_slots_grade_on_copies_and_leave_nothing(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    books = tmp_path / "in"
    books.mkdir()
    for k in range(8):
        shutil.copy(EXAMPLES / ("solution.ipynb" if k % 2 else "wrong-clockwise.ipynb"),
                    books / f"student{k}.ipynb")
    made: list[int] = []
    original = GradingSlot.warm_copies

    def recorded(self: GradingSlot, count: int, **kwargs: Any) -> list[Any]:
        copies = original(self, count, **kwargs)
        made.extend(pid for pid, _ in copies)
        return copies

    monkeypatch.setattr(GradingSlot, "warm_copies", recorded)
    seen: dict[str, Any] = {}
    pool_reported = threading.Event()
    monkeypatch.setattr(local, "grade_one", slot_zero_waits(pool_reported, local.grade_one))

    def look(result: Any) -> None:
        # A result the pool graded (reported from the feeder thread): its process holds no
        # warm parent of its own, and the copy is this process's child.
        if not seen and threading.current_thread() is not threading.main_thread():
            seen["pool_workers"] = [c.pid for p in pool_processes() for c in p.children()
                                    if "autograder.worker" in " ".join(c.cmdline())]
            seen["ours"] = [c.pid for c in psutil.Process().children()
                            if "autograder.worker" in " ".join(c.cmdline())]
            pool_reported.set()

    report = api.grade("hull", [books], out=tmp_path / "out", jobs=2, progress=False,
                       on_result=look)
    assert len(made) == 1
    assert seen["pool_workers"] == []
    assert made[0] in seen["ours"]
    by_name = {r.id: r for r in report.results}
    assert len(by_name) == 8 and {r.outcome for r in report.results} == {"graded"}
    right = {r.score for k, r in sorted(by_name.items()) if int(k[-1]) % 2}
    wrong = {r.score for k, r in sorted(by_name.items()) if not int(k[-1]) % 2}
    assert len(right) == 1 and len(wrong) == 1 and right != wrong
    assert _gone_or_zombie(made[0]) and not [
        c for c in psutil.Process().children() if "autograder.worker" in " ".join(c.cmdline())]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("autograder-slot-")]


def test_an_ordinary_users_pool_grades_on_copies_as_root_grades_alone(
        tmp_path: Path, ordinary_user_venv: tuple[envs.Env, Path]) -> None:
    env, source = ordinary_user_venv
    top = envs.shared_tempdir("numgrade-copies-")
    try:
        books, tmp = top / "books", top / "tmp"
        for folder in (books, tmp):
            folder.mkdir()
        for example in sorted(EXAMPLES.glob("*.ipynb")):
            for k in range(2):
                shutil.copy(example, books / f"{example.stem}-{k}.ipynb")
        envs.give_to(env.user or "", top)
        alone = api.grade("hull", [books], out=tmp_path / "root", jobs=1, progress=False)
        proc = env.run("python", "-m", "autograder", "grade", str(source / "assignments" / "hull"),
                       str(books), "--out", str(top / "out"), "--jobs", "2", "--no-progress",
                       cwd=top, env={"TMPDIR": str(tmp)})
        assert proc.returncode == 0, proc.stderr[-4000:]
        theirs = {p.parent.name: json.loads(p.read_text())
                  for p in (top / "out").glob("*/results.json")}
        assert set(theirs) == {r.id for r in alone.results}
        for result in alone.results:
            mine = theirs[result.id]
            assert (mine["score"], mine["extra_data"]["outcome"]) == (result.score, result.outcome), \
                result.id
            assert [t["status"] for t in mine["tests"]] == [t.status for t in result.tests], result.id
        assert not [p for p in tmp.iterdir() if p.name.startswith("autograder-slot-")]
    finally:
        shutil.rmtree(top, ignore_errors=True)


def test_the_feeder_hands_no_job_before_the_first_slot_checked_requirements(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # A pool process may be warm before slot 0 has checked the requirements: a missing
    # package still stops the run before any result is written.
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    books = tmp_path / "in"
    books.mkdir()
    for k in range(4):
        shutil.copy(EXAMPLES / "solution.ipynb", books / f"s{k}.ipynb")

    def missing(self: Grader) -> None:
        time.sleep(3)  # the pool is warm by now
        raise RuntimeError("a required package is missing (test)")

    monkeypatch.setattr(Grader, "check_requirements", missing)
    with pytest.raises(RuntimeError, match="missing"):
        api.grade("hull", [books], out=tmp_path / "out", jobs=2, progress=False)
    assert not list((tmp_path / "out").glob("*/results.json"))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("autograder-slot-")]
