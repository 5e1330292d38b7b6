"""Grading processes: each owns warm :class:`~autograder.grading.Grader` s and pulls jobs.

Grading is CPU-bound, blocking, and runs pytest in the grading process, so it
runs in separate processes (never on the web server's event loop or threads).
Each process keeps one Grader per assignment alive between jobs (rebuilt when
the assignment's checks change), claims a job, renews the lease from a small
thread while it grades, and records the result. These processes end when the
service dies, even by SIGKILL (``PR_SET_PDEATHSIG`` and a thread watching the
parent), and a killed job's lease runs out and another grader takes it.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autograder.assignment import checks_digest, load_assignment
from autograder.batch import error_result
from autograder.feedback import write_feedback
from autograder.grading import Grader, GradingOptions
from autograder.report import write_result
from autograder.results import SubmissionResult
from autograder.service import jobqueue
from autograder.service.course import Course, load_course
from autograder.service.db import make_engine, sessions
from autograder.service.models import Submission
from autograder.service.storage import Storage

_PR_SET_PDEATHSIG = 1


@dataclass(frozen=True)
class WorkerSettings:
    """What a grading process needs (picklable: it crosses a ``spawn``)."""

    course_path: str
    database_url: str
    lease_seconds: float = jobqueue.LEASE_SECONDS
    poll_seconds: float = 0.2


class _Graders:
    """One warm Grader per assignment, rebuilt when the assignment's checks change."""

    def __init__(self, course: Course) -> None:
        self.course = course
        self._held: dict[str, tuple[str, Grader]] = {}

    def get(self, name: str) -> Grader:
        policy = self.course.assignment(name)
        if policy is None:
            raise LookupError(f"assignment {name!r} is no longer in the course file")
        found = load_assignment(policy.spec)
        digest = checks_digest(found.root)
        held = self._held.get(name)
        if held is not None and held[0] == digest:
            return held[1]
        if held is not None:
            held[1].close()
        grader = Grader(found, GradingOptions(public_only=policy.public_only))
        self._held[name] = (digest, grader)
        return grader

    def close(self) -> None:
        for _, grader in self._held.values():
            grader.close()
        self._held.clear()


def _die_with_parent() -> None:
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the parent check in the loop still ends us
        pass


def grade_job(graders: _Graders, storage: Storage, submission: Submission,
              job: jobqueue.Claimed, *, max_tries: int) -> tuple[SubmissionResult, str]:
    """Grade one job into its own result folder; an engine failure becomes an "error" result."""
    out = storage.result_dir(job.job_id, job.claim)
    notebook = storage.upload_path(submission.sha256)
    title = submission.assignment
    try:
        if job.tries > max_tries:  # the grading process died this many times on it
            raise RuntimeError(f"grading stopped the grading process {job.tries - 1} times")
        grader = graders.get(submission.assignment)
        title = grader.assignment.title
        result = grader.grade(notebook, id=submission.user_id, out_dir=out)
    except (Exception, KeyboardInterrupt) as exc:  # the engine's failure: retried, shown to
        # the instructor. SIGINT is ignored in grading processes, so a KeyboardInterrupt
        # here comes from the engine itself, never from a person.
        result = _error(submission, notebook, exc)
        write_result(out, result)
    write_feedback(out, result, title=title)
    return result, str(out.relative_to(storage.root))


def _error(submission: Submission, notebook: Path, exc: BaseException) -> SubmissionResult:
    try:
        found = load_assignment(submission.assignment)
        return error_result(found, notebook, submission.user_id, exc)
    except Exception:
        return SubmissionResult(id=submission.user_id, source=str(notebook),
                                assignment=submission.assignment, key="", sha256=submission.sha256,
                                outcome="error", output=f"The grader failed: {exc}", tests=(),
                                execution_time=0.0, seed=0)


def _watch_parent(parent: int, graders: _Graders) -> None:
    """End this process when the service is gone (SIGKILL included).

    ``PR_SET_PDEATHSIG`` alone is not enough: the kernel clears it when a process's
    credentials change, which the engine may do while setting up a slot. So this
    thread also watches the parent id; it stops the warm workers (for a few
    seconds at most) and exits.
    """
    while os.getppid() == parent:
        time.sleep(0.5)
    closer = threading.Thread(target=graders.close, daemon=True)
    closer.start()
    closer.join(5)
    os._exit(1)


def _keep_lease(factory: Any, job: jobqueue.Claimed, settings: WorkerSettings,
                stop: threading.Event) -> None:
    while not stop.wait(settings.lease_seconds / 3):
        if not jobqueue.renew(factory, job, lease_seconds=settings.lease_seconds):
            return


def worker_main(settings: WorkerSettings, stop: Any, name: str) -> None:
    """The loop of one grading process: claim, grade, record, until ``stop`` is set."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the service; it stops us
    parent = os.getppid()
    course = load_course(settings.course_path)
    engine = make_engine(settings.database_url)
    factory = sessions(engine)
    storage = Storage(course.data_dir)
    graders = _Graders(course)
    threading.Thread(target=_watch_parent, args=(parent, graders), daemon=True).start()
    try:
        while not stop.is_set() and os.getppid() == parent:
            job = jobqueue.claim(factory, lease_seconds=settings.lease_seconds)
            if job is None:
                stop.wait(settings.poll_seconds)
                continue
            with factory() as session:
                submission = session.get(Submission, job.submission_id)
                assert submission is not None
                session.expunge(submission)
            halt = threading.Event()
            keeper = threading.Thread(target=_keep_lease, args=(factory, job, settings, halt),
                                      daemon=True)
            keeper.start()
            try:
                result, folder = grade_job(graders, storage, submission, job,
                                           max_tries=course.max_tries)
            finally:
                halt.set()
                keeper.join()
            jobqueue.finish(factory, job, result, folder, worker=name, max_tries=course.max_tries)
            _die_with_parent()  # again: grading may have changed credentials, which clears it
    finally:
        graders.close()
        engine.dispose()


class GradingPool:
    """``jobs`` grading processes pulling from the database queue."""

    def __init__(self, settings: WorkerSettings, jobs: int) -> None:
        self.settings = settings
        self.jobs = jobs
        self._context = multiprocessing.get_context("spawn")
        self._stop = self._context.Event()
        self._procs: list[Any] = []
        self._watch: threading.Thread | None = None
        self._closing = threading.Event()

    def start(self) -> None:
        for index in range(self.jobs):
            self._procs.append(self._spawn(index))
        self._watch = threading.Thread(target=self._restart_dead, daemon=True)
        self._watch.start()

    def _spawn(self, index: int) -> Any:
        proc = self._context.Process(target=worker_main, name=f"grader-{index}", daemon=True,
                                     args=(self.settings, self._stop, f"{os.getpid()}-{index}"))
        proc.start()
        return proc

    def _restart_dead(self) -> None:
        """A grading process that died (the machine ran out of memory, say) is replaced."""
        while not self._closing.wait(1.0):
            for index, proc in enumerate(self._procs):
                if not proc.is_alive() and not self._closing.is_set():
                    self._procs[index] = self._spawn(index)

    def stop(self, timeout: float = 30.0) -> None:
        self._closing.set()
        self._stop.set()
        deadline = time.monotonic() + timeout
        for proc in self._procs:
            proc.join(max(0.1, deadline - time.monotonic()))
            if proc.is_alive():
                proc.kill()
                proc.join(5)
