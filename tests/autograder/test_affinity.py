"""A worker slot runs on one core: its warm parent, its children and, during a submission,
the grader thread; the thread goes back where it could run after, and it can be turned off."""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from autograder.engine.student_process import StudentProcess
from autograder.errors import UsageError
from autograder.sandbox import affinity
from tests.support.assignments import CHECK, RIGHT, submission, write_double

CORES = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
needs_two_cores = pytest.mark.skipif(
    len(CORES) < 2, reason="needs Linux's sched_setaffinity and two cores this process may use "
                           "(a slot is pinned only then)")


def cores_of(pid: int) -> set[int]:
    return set(os.sched_getaffinity(pid))


def write_assignment(root: Path) -> tuple[Path, Path]:
    folder = write_double(root, "double", {"test_double.py": CHECK})
    return folder, submission(root / "submitted", "s1", RIGHT)


def test_slots_spread_over_the_cores_this_process_may_use(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(affinity.ENVIRONMENT_VARIABLE, raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3, 5, 8, 13}, raising=False)
    assert [affinity.slot_core(k) for k in range(6)] == [3, 5, 8, 13, 3, 5]
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {4}, raising=False)
    assert affinity.slot_core(0) is None  # one core: nothing to choose
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    for off in ("0", "off", "no"):
        monkeypatch.setenv(affinity.ENVIRONMENT_VARIABLE, off)
        assert affinity.slot_core(1) is None
    monkeypatch.setenv(affinity.ENVIRONMENT_VARIABLE, "1")
    assert affinity.slot_core(1) == 1
    monkeypatch.setenv(affinity.ENVIRONMENT_VARIABLE, "sometimes")
    with pytest.raises(UsageError, match="AUTOGRADER_PIN_CORES .from the environment. must be "
                                         "1 or 0; got 'sometimes'"):
        affinity.slot_core(0)


@needs_two_cores
def test_on_core_moves_only_this_thread_and_puts_it_back() -> None:
    before = cores_of(0)
    seen: dict[str, set[int]] = {}
    with pytest.raises(RuntimeError):
        with affinity.on_core(CORES[1]):
            seen["inside"] = cores_of(0)
            other = threading.Thread(target=lambda: seen.setdefault("thread", cores_of(0)))
            other.start()  # a new thread starts from its creator's mask, which is pinned
            other.join()
            raise RuntimeError("a failing block puts the thread back too")
    assert seen["inside"] == seen["thread"] == {CORES[1]}
    assert cores_of(0) == before
    with affinity.on_core(None):
        assert cores_of(0) == before


@needs_two_cores
@pytest.mark.parametrize("pinned", [True, False], ids=["pinned", "turned-off"])
def test_a_slot_and_its_grader_thread_share_one_core_during_a_submission(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, pinned: bool) -> None:
    if pinned:
        monkeypatch.delenv(affinity.ENVIRONMENT_VARIABLE, raising=False)
    else:
        monkeypatch.setenv(affinity.ENVIRONMENT_VARIABLE, "0")
    folder, submission = write_assignment(tmp_path)
    seen: list[dict[str, Any]] = []
    call = StudentProcess.call

    def watched(self: StudentProcess, *args: Any, **kwargs: Any) -> Any:
        assert self._pid is not None and self.slot.warm_parent is not None
        seen.append({"thread": cores_of(0), "child": cores_of(self._pid),
                     "warm parent": cores_of(self.slot.warm_parent)})
        return call(self, *args, **kwargs)

    monkeypatch.setattr(StudentProcess, "call", watched)
    before = cores_of(0)
    with Grader(load_assignment(folder)) as grader:
        core = grader._slot.core
        result = grader.grade(submission)
        assert cores_of(0) == before  # the thread is back where it could run
        if pinned:
            assert core == CORES[grader._slot.slot % len(CORES)]
            assert seen == [{"thread": {core}, "child": {core}, "warm parent": {core}}]
        else:
            assert core is None
            assert seen == [{"thread": before, "child": before, "warm parent": before}]
    assert result.score == result.max_score == 1.0
