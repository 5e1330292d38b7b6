"""A submission's child is forked ahead (``StudentProcess.launch``) and enters its sandbox
while the grader scans the notebook.

Its entry into the slot's cgroup waits for the kernel without using CPU; the grader
fills that wait. The child must still be the one that runs the notebook, get its cells
only at ``start``, have its sandbox entry counted on its CPU clock, leave nothing
behind when the grader gives up before ``start``, and give the same verdict as a
child forked at ``start``.
"""

from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Any

import psutil
import pytest

from autograder.engine import grader as grader_module
from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from autograder.engine.slot import GradingSlot
from autograder.engine.student_process import StudentProcess
from autograder.sandbox.policy import IsolationPolicy

ROOT = Path(__file__).resolve().parents[2]
SOLUTION = ROOT / "assignments" / "hull" / "examples" / "solution.ipynb"

pytestmark = pytest.mark.slow

CODE = "import os\nstarted_in = os.getpid()\ndef double(x):\n    return 2 * x\n"


def _gone(pid: int, seconds: float = 10.0) -> bool:
    """Whether process ``pid`` ended (and was reaped) within ``seconds``."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            if psutil.Process(pid).status() == psutil.STATUS_ZOMBIE:
                time.sleep(0.01)
                continue
        except psutil.NoSuchProcess:
            return True
        time.sleep(0.01)
    return False


def _session(slot: GradingSlot) -> StudentProcess:
    return StudentProcess(slot=slot, cells=[(0, CODE)], data_files=[],
                          policy=IsolationPolicy(), notebook_timeout=30, exclude=[ROOT])


def test_the_child_forked_ahead_is_the_one_that_runs_the_notebook() -> None:
    with GradingSlot(slot=0) as slot:
        slot.start()
        ahead = _session(slot)
        try:
            ahead.launch()
            child = ahead._pid
            assert child is not None and psutil.pid_exists(child)
            ahead.launch()  # a second call forks nothing more
            assert (ahead._pid, ahead._spawns) == (child, 1)
            report = ahead.start()
            assert ahead._spawns == 1 and ahead._pid == child
            assert all(cell.ok for cell in report.cells), report.cells
            assert "double" in report.functions
            value = ahead.request({"op": "call", "name": "double", "args": [21], "kwargs": {},
                                   "figures": False}, timeout=5, what="double()")
            assert value["value"] == 42
            # the sandbox's entry, before the cells came, is on the submission's clock
            assert report.cpu_seconds > 0
        finally:
            ahead.close()
        assert _gone(child)


def test_a_child_forked_ahead_and_never_started_leaves_nothing_behind() -> None:
    with GradingSlot(slot=0) as slot:
        slot.start()
        ahead = _session(slot)
        ahead.launch()
        child, workdir = ahead._pid, ahead._workdir
        assert child is not None and workdir is not None and workdir.is_dir()
        ahead.close()
        assert _gone(child), "the child forked ahead outlived its session"
        assert not workdir.exists()
        # the slot serves the next submission as usual
        after = _session(slot)
        try:
            report = after.start()
            assert all(cell.ok for cell in report.cells)
        finally:
            after.close()


def test_a_warm_slot_forks_the_child_before_the_scan_with_the_same_verdict(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[dict[str, Any]] = []
    scan = grader_module.scan_sources

    def watched(*args: Any, **kwargs: Any) -> Any:
        parent = grader._slot.warm_parent
        seen.append({"children": len(psutil.Process(parent).children()) if parent else 0,
                     "cores": os.sched_getaffinity(0)})
        return scan(*args, **kwargs)

    monkeypatch.setattr(grader_module, "scan_sources", watched)
    copies = []
    for name in ("alice", "bob"):
        copies.append(tmp_path / name / "hull.ipynb")
        copies[-1].parent.mkdir()
        shutil.copyfile(SOLUTION, copies[-1])
    with Grader(load_assignment("hull")) as grader:
        first = grader.grade(copies[0], id="alice")
        second = grader.grade(copies[1], id="bob")
        core = grader._slot.core
        left = psutil.Process(grader._slot.warm_parent).children()
    # the first submission: the warm parent was still starting, so nothing was forked ahead
    assert seen[0]["children"] == 0
    # the second: its child was forked and was entering its sandbox during the scan, with
    # this thread on the slot's core (pinning on) as while any child of the slot lives
    assert seen[1]["children"] == 1
    if core is not None:
        assert seen[1]["cores"] == {core}
    assert os.sched_getaffinity(0) == seen[0]["cores"]  # where it ran before, after
    assert left == []
    assert first.score == second.score == first.max_score
    assert [(t.name, t.score) for t in first.tests] == [(t.name, t.score) for t in second.tests]
