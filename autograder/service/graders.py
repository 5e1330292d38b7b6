"""Grading processes: each owns warm :class:`~autograder.engine.grader.Grader` s and pulls jobs.

Grading is CPU-bound, blocking, and runs pytest in the grading process, so it
runs in separate processes (never on the web server's event loop or threads).
Each process keeps one Grader per assignment alive between jobs (rebuilt when
the assignment's checks change), claims a job, renews the lease from a small
thread while it grades, and records the result. The lease is renewed only while the
submission is within its budget (:meth:`Grader.wall_limit`, with a margin): a grading
process still busy after that is stuck, so it ends itself, the pool starts another,
and the job's lease runs out for the next grader (after ``max_tries`` the job fails
for the instructor), so no single upload holds the queue. :mod:`autograder.service.pool`
starts these processes and ties their lives to the service's; a job whose
grading process died has its lease run out, and another grader takes it.
"""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from pathlib import Path
from typing import Any, Callable

from autograder.engine.assignment import checks_digest, load_assignment
from autograder.engine.grader import Grader, GradingOptions, error_result, forget_check_modules
from autograder.results.model import SubmissionResult
from autograder.results.store import write_submission
from autograder.service import jobqueue
from autograder.service.course import Course, load_course
from autograder.service.db import make_engine, sessions
from autograder.service.models import Submission
from autograder.service.settings import GraderSettings
from autograder.service.storage import Storage


class _Graders:
    """One warm Grader per assignment, rebuilt when the assignment's checks change."""

    def __init__(self, course: Course) -> None:
        self.course = course
        self._held: dict[str, tuple[str, Grader]] = {}
        self._last: tuple[str, str] | None = None

    def get(self, name: str) -> Grader:
        policy = self.course.assignment(name)
        if policy is None:
            raise LookupError(f"assignment {name!r} is no longer in the course file")
        found = load_assignment(policy.spec)
        digest = checks_digest(found.root)
        if self._last != (name, digest):
            forget_check_modules(*[load_assignment(p.spec).root / "checks"
                                  for p in self.course.assignments])
            self._last = (name, digest)
        held = self._held.get(name)
        if held is not None and held[0] == digest:
            return held[1]
        if held is not None:
            held[1].close()
        grader = Grader(found, GradingOptions(public_only=policy.public_only))
        self._held[name] = (digest, grader)
        return grader

    def drop(self, name: str) -> None:
        """Forget the Grader of ``name`` and every imported check after an engine failure.

        A retry then starts from the files on disk: a check module that failed to
        import must not linger half-made in ``sys.modules`` (a later run in the same
        process could otherwise skip that file and grade with the other checks only).
        """
        held = self._held.pop(name, None)
        self._last = None
        if held is not None:
            try:
                held[1].close()
            except Exception:  # closing a broken slot must not hide the failure being handled
                pass

    def close(self) -> None:
        for _, grader in self._held.values():
            grader.close()
        self._held.clear()


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
        graders.drop(submission.assignment)
        result = write_submission(out, engine_error(submission, notebook, exc), title=title)
    return result, str(out.relative_to(storage.root))


def engine_error(submission: Submission, notebook: Path, exc: BaseException) -> SubmissionResult:
    """The "error" result of ``submission`` when the engine failed on it (retried, never a zero)."""
    try:
        found = load_assignment(submission.assignment)
        return error_result(found, notebook, submission.user_id, exc)
    except Exception:
        return SubmissionResult(id=submission.user_id, source=str(notebook),
                                assignment=submission.assignment, key="", sha256=submission.sha256,
                                outcome="error", output=f"The grader failed: {exc}", tests=(),
                                execution_time=0.0, seed=0)


def load_submission(factory: Any, job: jobqueue.Claimed) -> Submission:
    """The claimed job's submission, detached from its session."""
    with factory() as session:
        submission = session.get(Submission, job.submission_id)
        assert submission is not None
        session.expunge(submission)
    return submission


log = logging.getLogger("autograder.service.graders")

#: a grading may take this much longer than its submission's wall limit (the checks' own
#: work on the trusted side, collecting them, writing the result), and this factor more
OVERRUN_SLACK = 300.0
OVERRUN_FACTOR = 1.5


def grading_deadline(graders: _Graders, submission: Submission) -> float | None:
    """When (``time.monotonic()``) grading ``submission`` is overdue; ``None`` if its
    assignment cannot be loaded (grading then fails at once, with that message)."""
    try:
        limit = graders.get(submission.assignment).wall_limit()
    except Exception:
        return None
    return time.monotonic() + OVERRUN_FACTOR * limit + OVERRUN_SLACK


def _replace_this_process() -> None:
    """End a grading process stuck past its job's deadline; the pool starts a new one."""
    log.error("grading process %d: a job ran past its whole time budget; this process ends "
              "and the job's lease runs out for another try", os.getpid())
    os.kill(os.getpid(), signal.SIGKILL)


def _keep_lease(factory: Any, job: jobqueue.Claimed, settings: GraderSettings,
                stop: threading.Event, *, deadline: float | None = None,
                overrun: Callable[[], None] = _replace_this_process) -> None:
    """Renew ``job``'s lease until ``stop`` is set; past ``deadline``, stop renewing and
    call ``overrun`` (which ends the stuck grading process)."""
    while not stop.wait(settings.lease_seconds / 3):
        if deadline is not None and time.monotonic() >= deadline:
            overrun()
            return
        if not jobqueue.renew(factory, job, lease_seconds=settings.lease_seconds):
            return


def grader_main(settings: GraderSettings, stop: Any, name: str, parent: int,
                wake: Any = None, graded: Any = None) -> None:
    """The loop of one grading process: claim, grade, record, until ``stop`` is set.

    Started through :func:`autograder.service.pool.grader_entry`, which has already
    tied this process's life to the service's (``parent``). With nothing to claim it
    waits ``settings.poll_seconds``, or until ``wake`` (an event the service sets when
    it queues a job) is set. The id of each submission recorded goes on ``graded`` (a
    queue the web process reads to answer the requests waiting for it).
    """
    course = load_course(settings.course_path)
    engine = make_engine(settings.database_url)
    factory = sessions(engine)
    storage = Storage(course.data_dir)
    graders = _Graders(course)
    try:
        while not stop.is_set() and os.getppid() == parent:
            job = jobqueue.claim(factory, lease_seconds=settings.lease_seconds)
            if job is None:
                idle(stop, wake, settings.poll_seconds)
                continue
            submission = load_submission(factory, job)
            halt = threading.Event()
            keeper = threading.Thread(target=_keep_lease, args=(factory, job, settings, halt),
                                      kwargs={"deadline": grading_deadline(graders, submission)},
                                      daemon=True)
            keeper.start()
            try:
                result, folder = grade_job(graders, storage, submission, job,
                                           max_tries=course.max_tries)
            finally:
                halt.set()
                keeper.join()
            jobqueue.finish(factory, job, result, folder, worker=name, max_tries=course.max_tries)
            tell_graded(graded, job.submission_id)
    finally:
        graders.close()
        engine.dispose()


def idle(stop: Any, wake: Any, seconds: float) -> None:
    """Wait ``seconds`` for work; less when ``wake`` is set (a job was queued) or, without
    one, when ``stop`` is. Every idle process wakes, and the claim decides who grades."""
    if wake is None:
        stop.wait(seconds)
        return
    if wake.wait(seconds):
        wake.clear()  # a set after this clear is not lost: the loop claims next


def tell_graded(graded: Any, sub_id: int) -> None:
    """Put ``sub_id`` on ``graded`` (None: nobody listens); never blocks, never raises."""
    if graded is not None:
        try:
            graded.put_nowait(sub_id)
        except Exception:  # full or closed: the waiting requests look again within a second
            pass
