"""The local backend: this process grades as one slot, a pool of slot processes beside it (``--jobs N``).

Each slot holds one :class:`Grader` and its warm worker and grades one file at a
time, writing the result's files itself (same machine, same file system). This
process is slot 0. Once it has collected its checks, the pool's ``N - 1`` slot
processes are forked from it (:meth:`Grader.sibling`): they hold the engine's
imports and the collected checks from the start, where spawned processes would
import and collect again (about a CPU second each, on the cores the batch grades
on). Nor do they import numpy, matplotlib and IPython: once slot 0's warm
parent is ready, and before its first submission, it forks a copy of itself for
each of them (:meth:`GradingSlot.warm_copies`), which this process adopts as its
own child and hands to a pool process (:meth:`GradingSlot.adopt`). So every slot is
warm about when slot 0 is, and the start-up costs one import of the libraries, not
``N``. A pool process gets a file only once it is ready and slot
0 has checked the assignment's requirements. A pool rebuilt after a slot process
died, or started by a process that runs threads of its own (a fork copies one
thread, and a lock another held would stay locked), is spawned instead, away from
slot 0's core, and its processes start warm parents of their own when the copies
went to the first pool. Every slot takes the next file when it is free.
"""

from __future__ import annotations

import collections
import contextlib
import multiprocessing
import multiprocessing.util
import os
import queue
import socket
import sys
import threading
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any, Sequence

from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.grader import Grader, GradingOptions, error_result
from autograder.engine.slot import GradingSlot
from autograder.results.model import SubmissionResult
from autograder.results.store import write_submission
from autograder.runners.jobs import Finished, Job
from autograder.sandbox.support import probe_support

# One Grader per pool process: the warm worker is the point of the pool. This is the
# package's only module-level state, and it lives only in pool processes.
_GRADER: Grader | None = None


def grade_one(grader: Grader, path: Path, sub_id: str, out_dir: Path) -> SubmissionResult:
    """Grade one file into ``out_dir/<id>/``; a grader failure becomes an "error" result."""
    folder = out_dir / sub_id
    try:
        return grader.grade(path, id=sub_id, out_dir=folder)
    except Exception as exc:  # the grader's own failure: record it, never lose the file
        return write_submission(folder, error_result(grader.assignment, path, sub_id, exc),
                                title=grader.assignment.title)


def _init_slot(counter: Any, assignment_root: str, options: GradingOptions,
               copies: Any | None, cores: set[int] | None) -> None:
    """A spawned pool process's slot (a pool rebuilt after a death, or a batch's process
    that could not fork): it imports the engine and collects the checks itself.

    ``copies`` (a queue; None in a pool rebuilt after a death) gives each process
    one item: a copy's pid and control socket, or None when slot 0 made no copy for
    it (then this slot starts its own warm parent). ``cores``: the cores the batch
    may use; this process was started away from slot 0's core (see
    :meth:`_PoolFeeder.run`) and gets them all back here, before its slot picks one.
    """
    global _GRADER
    if cores is not None:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(0, cores)
    worker = GradingSlot(slot=_next_slot(counter))
    _GRADER = _closed_at_exit(Grader(load_assignment(Path(assignment_root)), options,
                                     started_slot=worker))
    try:
        _GRADER.collect()  # while slot 0's warm parent imports
    except Exception:  # prepare() and grade() meet it again; grade() reports it
        pass
    _warm(worker, copies)


def _init_forked_slot(counter: Any, parent: Grader, copies: Any) -> None:
    """A pool process forked from the batch's process once slot 0 collected its checks.

    It holds the engine's imports and a copy of the collected checks already
    (:meth:`Grader.sibling`), where a spawned process would spend about a CPU second
    importing and collecting them again, on the cores the batch grades on.
    """
    global _GRADER
    worker = GradingSlot(slot=_next_slot(counter))
    _GRADER = _closed_at_exit(parent.sibling(worker))
    _warm(worker, copies)


def _next_slot(counter: Any) -> int:
    with counter.get_lock():
        slot = int(counter.value)
        counter.value += 1
    return slot


def _closed_at_exit(grader: Grader) -> Grader:
    # A pool process ends through os._exit, which skips atexit: multiprocessing's own
    # exit finalizers are what run there. Without this the slot's warm worker and its
    # home folder (``autograder-slot-*``) outlived every ``--jobs N`` run.
    multiprocessing.util.Finalize(grader, grader.close, exitpriority=10)
    return grader


def _warm(worker: GradingSlot, copies: Any | None) -> None:
    """Adopt this process's copy of slot 0's warm parent, if it has one, and get ready."""
    assert _GRADER is not None
    copy = _wait_for_copy(copies) if copies is not None else None
    if copy is not None:
        worker.adopt(*copy)
    _GRADER.prepare()


def _wait_for_copy(copies: Any) -> tuple[int, socket.socket] | None:
    """This process's item from ``copies``; exit if the process that gives them died."""
    parent = multiprocessing.parent_process()
    while True:
        try:
            item = copies.get(timeout=0.5)
        except queue.Empty:
            if parent is not None and not parent.is_alive():
                raise SystemExit("the grading process that started this slot is gone") from None
            continue
        return None if item is None else (int(item[0]), item[1])


def _slot_ready() -> bool:
    return _GRADER is not None


def _grade_in_slot(path: str, sub_id: str, out_dir: str) -> dict[str, Any]:
    assert _GRADER is not None
    return grade_one(_GRADER, Path(path), sub_id, Path(out_dir)).to_dict()


class LocalBackend:
    """``jobs`` slots (default: the number of cores); slot 0 runs in this process.

    ``started_slot``, a slot whose warm parent was started ahead, is slot 0's.
    """

    def __init__(self, jobs: int | None = None, *, started_slot: GradingSlot | None = None) -> None:
        self.jobs = jobs
        self.started_slot = started_slot

    def run(self, assignment: Assignment, options: GradingOptions, jobs: Sequence[Job],
            out_dir: Path, finished: Finished) -> None:
        slots = max(1, min(self.jobs or os.cpu_count() or 1, len(jobs) or 1))
        queue = _Queue(jobs)
        with Grader(assignment, options, started_slot=self.started_slot) as grader:
            if slots == 1:
                grader.prepare()
                grader.check_requirements()  # before any result: a missing package stops the run
                while (job := queue.take()) is not None:
                    finished(grade_one(grader, job.path, job.id, out_dir))
                return
            # Cached from here on: the sweep after a submission may probe the sandbox, which
            # forks this process, and a fork is safest before the pool's threads exist.
            probe_support()
            _grade_beside_pool(grader, options, slots - 1, queue, out_dir, finished)


class _Queue:
    """The jobs no slot has taken yet, shared by this process's slot and the pool's feeder."""

    def __init__(self, jobs: Sequence[Job]) -> None:
        self._jobs = collections.deque(jobs)
        self._lock = threading.Lock()
        self._closed = False

    def take(self) -> Job | None:
        with self._lock:
            return self._jobs.popleft() if self._jobs and not self._closed else None

    def give_back(self, job: Job) -> None:
        with self._lock:
            if not self._closed:
                self._jobs.appendleft(job)

    def __bool__(self) -> bool:
        with self._lock:
            return bool(self._jobs) and not self._closed

    def close(self) -> None:
        """Hand out nothing more (Ctrl-C, or a failure in another slot)."""
        with self._lock:
            self._closed = True
            self._jobs.clear()


def _grade_beside_pool(grader: Grader, options: GradingOptions, processes: int, queue: _Queue,
                       out_dir: Path, finished: Finished) -> None:
    """Grade in this thread while a feeder thread keeps ``processes`` pool processes busy."""
    lock = threading.Lock()

    def report(result: SubmissionResult) -> None:
        with lock:
            finished(result)

    feeder = _PoolFeeder(grader.assignment, options, processes, queue, out_dir, report,
                         avoid=grader.core)
    try:
        copies: list[tuple[int, socket.socket]] = []
        try:
            grader.prepare(wait=False)  # this slot's checks first, then the pool:
            feeder.fork_pool(grader)  # forked with them, while no other thread runs
            feeder.start()  # (or spawned from there, away from this slot's core)
            grader.prepare()
            copies = grader.warm_copies(processes)  # before this slot's first submission
        finally:
            feeder.give(copies)  # a pool process waits for its item: always one each
        grader.check_requirements()  # before any result: a missing package stops the run
        feeder.checked.set()
        while (job := queue.take()) is not None:
            report(grade_one(grader, job.path, job.id, out_dir))
    except BaseException:
        queue.close()  # the pool finishes the files it holds (whole results), and stops
        raise
    finally:
        feeder.checked.set()
        if feeder.ident is not None:  # started
            feeder.join()
        for _, control in copies:  # handed over (a pool process holds its own end now)
            control.close()
    if feeder.failure is not None:
        raise feeder.failure


class _PoolFeeder(threading.Thread):
    """Hands a job to a pool process only once that process is ready (warm), one job each.

    Until then this process's slot takes every job, so a small batch never waits for
    the pool's start-up. If a slot process dies, the pool is rebuilt and its job is
    retried once (a second death is an "error" result for that job); a pool that
    broke before any of its processes was ready is not rebuilt, and this process's
    slot grades what is left.
    """

    def __init__(self, assignment: Assignment, options: GradingOptions, processes: int,
                 queue: _Queue, out_dir: Path, report: Finished, *, avoid: int | None) -> None:
        super().__init__(name="autograder-pool-feeder", daemon=True)
        self._avoid = avoid  # slot 0's core
        self._cores: set[int] | None = None
        self._assignment, self._options, self._processes = assignment, options, processes
        self._queue, self._out_dir, self._report = queue, out_dir, report
        self._attempts: dict[str, int] = {}
        self.failure: BaseException | None = None
        #: set once slot 0 checked the requirements (or stopped): no job is handed out before
        self.checked = threading.Event()
        self._context = multiprocessing.get_context("spawn")
        #: slot 0's warm parent copies for the first pool's processes (see :func:`_warm`)
        self._copies: Any = self._context.Queue()
        self._first_pool = True
        #: the first pool, when :meth:`fork_pool` started it, and its "ready" calls
        self._forked: tuple[ProcessPoolExecutor, dict[Future[Any], Job | None]] | None = None
        self._gave_up = False

    def give(self, copies: Sequence[tuple[int, socket.socket]]) -> None:
        """One item per pool process: a warm parent copy, or None (it starts its own)."""
        for index in range(self._processes):
            self._copies.put(copies[index] if index < len(copies) else None)

    def run(self) -> None:
        # The pool's processes import the engine while slot 0's warm parent imports on its
        # core: started from this thread kept off that core, they leave it alone (and slot
        # 0's first result is not later than without a pool). Affinity is per thread and
        # inherited by what the thread starts; a pool process takes every core back.
        if self._avoid is not None:
            with contextlib.suppress(OSError):
                cores = os.sched_getaffinity(0)
                if cores - {self._avoid}:
                    os.sched_setaffinity(0, cores - {self._avoid})
                    self._cores = cores
        try:
            while self._one_pool():
                pass
        except BaseException as exc:  # the pool itself could not be run
            self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        """Stop handing out jobs; ``exc`` is raised again in the thread that runs the batch."""
        if self.failure is None:
            self.failure = exc
        self._queue.close()

    def fork_pool(self, grader: Grader) -> None:
        """Start the first pool now, its processes forked from this one with ``grader``'s
        collected checks (see :func:`_init_forked_slot`); else :meth:`run` spawns it.

        Call it before :meth:`start`, from the batch's thread: a fork copies only the
        thread that makes it, and a lock another thread held would stay locked in the
        copy. So this process forks only while no other thread of it runs (a caller
        with threads of its own, such as a notebook's kernel, gets spawned processes).
        """
        if threading.active_count() > 1 or "fork" not in multiprocessing.get_all_start_methods():
            return
        context = multiprocessing.get_context("fork")
        self._forked = self._start_pool(context, _init_forked_slot, (grader, self._copies))
        self._first_pool = False  # the copies are this pool's; a rebuilt one starts its own
        # None: the instructor was told; this process's slot grades every file
        self._gave_up = self._forked is None

    def _start_pool(self, context: Any, initializer: Any, initargs: tuple[Any, ...],
                    ) -> tuple[ProcessPoolExecutor, dict[Future[Any], Job | None]] | None:
        """A pool of ``processes`` slot processes, started now, and one "ready" call each;
        None (and a word to the instructor) when multiprocessing cannot set one up.

        Each process's ``initializer`` gets the slot counter (slot 0 is this process's),
        then ``initargs``.
        """
        try:
            counter = context.Value("i", 1)
            pool = ProcessPoolExecutor(max_workers=self._processes, mp_context=context,
                                       initializer=initializer, initargs=(counter, *initargs))
            try:
                # A call runs once its process's initializer is done: its answer says "ready".
                # (With "fork", the first call starts every process, from this thread.)
                running: dict[Future[Any], Job | None] = {
                    pool.submit(_slot_ready): None for _ in range(self._processes)}
            except BaseException:
                pool.shutdown(wait=False, cancel_futures=True)
                raise
        except OSError as exc:
            # multiprocessing could not set the pool up (seen once in CI: its resource
            # tracker's pipe was broken): nothing is lost, this process's slot grades
            # every file that is left, and the instructor is told why it is slower.
            print(f"autograder: could not start {self._processes} more grading "
                  f"process(es) ({type(exc).__name__}: {exc}); this process grades every "
                  "remaining submission.", file=sys.stderr, flush=True)
            return None
        return pool, running

    def _one_pool(self) -> bool:
        """Feed one pool until no job is left; True when it broke and is worth rebuilding."""
        started, self._forked = self._forked, None
        if started is None:
            if self._gave_up or not self._queue:
                return False
            # A rebuilt pool starts its own warm parents: the copies were for the first one.
            copies, self._first_pool = (self._copies if self._first_pool else None), False
            started = self._start_pool(self._context, _init_slot,
                                       (str(self._assignment.root), self._options, copies,
                                        self._cores))
            if started is None:
                return False
        pool, running = started
        with pool:
            broken = ready = False
            while running:
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                for future in done:
                    job = running.pop(future)
                    died = self._collect(future, job)
                    broken = broken or died
                    ready = ready or (job is None and not died)
                    if job is None and not died:
                        self.checked.wait()
                    if not broken and (job := self._queue.take()) is not None:
                        running[pool.submit(_grade_in_slot, str(job.path), job.id,
                                            str(self._out_dir))] = job
            return broken and ready

    def _collect(self, future: Future[Any], job: Job | None) -> bool:
        """Report ``job``'s result (None: a ready call); True when its slot process died."""
        try:
            try:
                answer = future.result()
            except BrokenProcessPool as exc:
                if job is None:
                    return True
                self._attempts[job.id] = self._attempts.get(job.id, 0) + 1
                if self._attempts[job.id] < 2:
                    self._queue.give_back(job)
                    return True
                self._report(write_submission(self._out_dir / job.id, error_result(
                    self._assignment, job.path, job.id, exc), title=self._assignment.title))
                return True
            if job is not None:
                self._report(SubmissionResult.from_dict(answer))
        except BaseException as exc:  # Ctrl-C in a slot process, or ``finished`` failed:
            self._fail(exc)  # the results of the other files still running are reported
        return False


__all__ = ["LocalBackend"]
