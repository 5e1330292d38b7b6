"""The local backend: a pool of slot processes on this machine (``--jobs N``).

Each slot is a separate (trusted) Python process holding one :class:`Grader`
and its warm worker; the pool hands it one file at a time, and the slot writes
the result's files itself (same machine, same file system).
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.util
import os
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, Sequence

from autograder.assignment import Assignment, load_assignment
from autograder.backends import Finished, Job
from autograder.batch import error_result, grade_one, store_error
from autograder.grading import Grader, GradingOptions
from autograder.results import SubmissionResult

# One Grader per pool process: the warm worker is the point of the pool. This is the
# package's only module-level state, and it lives only in pool processes.
_GRADER: Grader | None = None


def _init_slot(assignment_root: str, options: GradingOptions, counter: Any) -> None:
    global _GRADER
    with counter.get_lock():
        slot = counter.value
        counter.value += 1
    _GRADER = Grader(load_assignment(Path(assignment_root)), options, slot=slot)
    # A pool process ends through os._exit, which skips atexit: multiprocessing's own
    # exit finalizers are what run there. Without this the slot's warm worker and its
    # home folder (``autograder-slot-*``) outlived every ``--jobs N`` run.
    multiprocessing.util.Finalize(_GRADER, _GRADER.close, exitpriority=10)


def _grade_in_slot(path: str, sub_id: str, out_dir: str) -> dict[str, Any]:
    assert _GRADER is not None
    return grade_one(_GRADER, Path(path), sub_id, Path(out_dir)).to_dict()


class LocalBackend:
    """``jobs`` slot processes (default: the number of cores); one slot runs in this process."""

    def __init__(self, jobs: int | None = None) -> None:
        self.jobs = jobs

    def run(self, assignment: Assignment, options: GradingOptions, jobs: Sequence[Job],
            out_dir: Path, finished: Finished) -> None:
        slots = max(1, min(self.jobs or os.cpu_count() or 1, len(jobs) or 1))
        if slots == 1:
            with Grader(assignment, options) as grader:
                for job in jobs:
                    finished(grade_one(grader, job.path, job.id, out_dir))
            return
        _run_pool(assignment, options, slots, list(jobs), out_dir, finished)


def _run_pool(assignment: Assignment, options: GradingOptions, slots: int, work: list[Job],
              out_dir: Path, finished: Finished) -> None:
    """Run ``work`` on ``slots`` processes; if a slot process dies, rebuild and retry once."""
    context = multiprocessing.get_context("spawn")
    attempts: dict[str, int] = {}
    pending = list(work)
    while pending:
        counter = context.Value("i", 0)
        broken: list[Job] = []
        with ProcessPoolExecutor(max_workers=slots, mp_context=context, initializer=_init_slot,
                                 initargs=(str(assignment.root), options, counter)) as pool:
            futures: dict[Future[dict[str, Any]], Job] = {
                pool.submit(_grade_in_slot, str(j.path), j.id, str(out_dir)): j for j in pending}
            for future in as_completed(futures):
                job = futures[future]
                try:
                    finished(SubmissionResult.from_dict(future.result()))
                except BrokenProcessPool as exc:
                    attempts[job.id] = attempts.get(job.id, 0) + 1
                    if attempts[job.id] >= 2:
                        finished(store_error(out_dir, error_result(assignment, job.path, job.id, exc),
                                             assignment.title))
                    else:
                        broken.append(job)
        pending = broken


__all__ = ["LocalBackend"]
