"""The dispatcher: the service's gradings on a Dask cluster (``autograder serve --dask``).

One process, started by :mod:`autograder.service.pool` and tied to the
service's life like a grading process, takes the place of the local graders.
It claims jobs from the same database queue, sends each submission's bytes to
the cluster through the Dask backend (:class:`~autograder.runners.dask_cluster.GradingStream`:
one :class:`~autograder.runners.dask_cluster.GradingSlots` per assignment
bundle, :func:`~autograder.runners.dask_cluster.grade_task`), and keeps at
most as many jobs out as the cluster has grading slots. One thread renews the
lease of every job that is out, until the grading's whole budget is spent:
a grading still out then gets an "error" result and is tried again. Each result is written into the job's result
folder as :func:`autograder.service.graders.grade_job` writes it and recorded
with :func:`autograder.service.jobqueue.finish`.

An engine failure (the scheduler unreachable or gone, a worker lost, workers
that refuse the slots) is an "error" result, retried under the course's
``max_tries`` like a local grader's failure and never shown as a zero. A
grading whose workers died while other gradings were out beside it proves
nothing (Dask counts a death against every task on the dying worker, and when
all workers die, hands the waiting ones to the first worker back): it is a
suspect, sent again alone once nothing else is out, with nothing new claimed
meanwhile, and only one that kills workers alone gets the "error" result
(:func:`~autograder.runners.dask_cluster.killed_worker`). So a submission that
kills workers never spends an innocent one's tries. A job
whose dispatcher died keeps its claim only until its lease runs out; then it is
taken again, so each job is still recorded once.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session, sessionmaker

from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.grader import (
    GradingOptions,
    client_key,
    error_result,
    submission_wall_limit,
)
from autograder.errors import EngineError
from autograder.results.model import SubmissionResult
from autograder.results.store import write_submission
from autograder.runners.backends import load_dask_backend
from autograder.service import jobqueue
from autograder.service.course import load_course
from autograder.service.db import make_engine, sessions
from autograder.service.graders import (OVERRUN_FACTOR, OVERRUN_SLACK, engine_error, idle,
                                        load_submission, tell_graded)
from autograder.service.models import Submission
from autograder.service.settings import GraderSettings
from autograder.service.storage import Storage

log = logging.getLogger("autograder.service.dispatch")

#: seconds to wait for a remote scheduler before the job in hand gets an "error" result
#: (``--dask-connect-timeout`` of ``autograder serve`` replaces it)
CONNECT_SECONDS = 10.0
#: seconds a stopping dispatcher waits for the gradings it has out (the pool waits 30)
DRAIN_SECONDS = 20.0
#: seconds between asking the workers, while none grades, whether they all refused
REFUSAL_CHECK_SECONDS = 5.0


@dataclass(frozen=True)
class _Flight:
    """A claimed job and what its grading needs; ``slots`` once it is out on the cluster."""

    job: jobqueue.Claimed
    submission: Submission
    notebook: Path
    assignment: Assignment | None = None
    options: GradingOptions | None = None
    slots: str = ""
    #: when (``time.monotonic()``) the grading is overdue: past it, its lease is no longer
    #: renewed and it gets an "error" result (retried), as a stuck local grader is replaced
    deadline: float | None = None
    #: whether another grading was out beside it (its workers' deaths may be another's doing)
    shared: bool = False

    @property
    def title(self) -> str:
        return self.assignment.title if self.assignment is not None else self.submission.assignment


def _deadline(assignment: Assignment, options: GradingOptions) -> float:
    """When a grading sent now is overdue: its whole time budget, with the slack of a local grader."""
    return (time.monotonic() + OVERRUN_FACTOR * submission_wall_limit(assignment, options)
            + OVERRUN_SLACK)


class _Leases:
    """Renews the lease of every job that is out, every third of the lease, from one thread;
    never past the job's deadline (a grading stuck on the cluster must not hold its job forever)."""

    def __init__(self, factory: sessionmaker[Session], lease_seconds: float) -> None:
        self._factory, self._seconds = factory, lease_seconds
        self._held: dict[int, tuple[jobqueue.Claimed, float | None]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="keep-leases")

    def start(self) -> None:
        self._thread.start()

    def hold(self, job: jobqueue.Claimed, deadline: float | None = None) -> None:
        with self._lock:
            self._held[job.job_id] = (job, deadline)

    def release(self, job: jobqueue.Claimed) -> None:
        with self._lock:
            self._held.pop(job.job_id, None)

    def _run(self) -> None:
        while not self._stop.wait(self._seconds / 3):
            with self._lock:
                held = list(self._held.values())
            for job, deadline in held:
                if deadline is not None and time.monotonic() >= deadline:
                    continue  # overdue: the dispatcher records its error; the lease runs out
                try:
                    if not jobqueue.renew(self._factory, job, lease_seconds=self._seconds):
                        self.release(job)  # taken over: finishing it will find it "lost"
                except SQLAlchemyError as exc:  # a database hiccup: the next round tries again
                    log.warning("could not renew the lease of job %s: %s", job.job_id, exc)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()


class Dispatcher:
    """Claims jobs, keeps up to one per grading slot out on the cluster, records results."""

    def __init__(self, settings: GraderSettings, name: str) -> None:
        assert settings.dask is not None
        self.settings = settings
        self.name = name
        self.course = load_course(settings.course_path)
        self.engine = make_engine(settings.database_url)
        self.factory = sessions(self.engine)
        self.storage = Storage(self.course.data_dir)
        self.stream = load_dask_backend().GradingStream(settings.dask, connect_timeout=CONNECT_SECONDS)
        self.leases = _Leases(self.factory, settings.lease_seconds)
        self.out: dict[Any, _Flight] = {}
        self._suspects: deque[_Flight] = deque()  # lost their workers beside others: go again alone
        self._lone: Any = None  # the suspect out alone, if one is
        #: where the ids of recorded submissions go (see autograder.service.waits)
        self.graded: Any = None
        self._checked = time.monotonic()

    def run(self, stop: Any, parent: int, wake: Any = None) -> None:
        """Dispatch until ``stop`` is set or the service is gone; then wait briefly for what is out.
        ``wake``: see :func:`autograder.service.graders.idle`."""
        self.leases.start()
        try:
            self._warm_up()
            while not stop.is_set() and os.getppid() == parent:
                if self._suspects and not self.out:
                    self._send_suspect()
                    continue
                if self._room() and self._send_one():
                    continue
                if self.out:
                    self._collect(self.settings.poll_seconds)
                else:
                    idle(stop, wake, self.settings.poll_seconds)
            deadline = time.monotonic() + DRAIN_SECONDS
            while self.out and time.monotonic() < deadline and os.getppid() == parent:
                # what is left, and a suspect not sent again, keeps no lease and is graded again later
                self._collect(1.0)
        finally:
            self.leases.stop()
            try:
                self.stream.close()
            finally:
                self.engine.dispose()

    def _warm_up(self) -> None:
        """Connect (for ``local:N``: start the cluster) before the first job needs it."""
        try:
            self.stream.client
        except Exception as exc:  # the first job in hand records it as its "error" result
            log.warning("the Dask cluster is not reachable yet: %s", exc)

    def _room(self) -> bool:
        if self._suspects or self._lone in self.out:
            return False  # a suspect is graded alone: nothing new goes out before it is back
        if not self.stream.connected:
            return not self.out  # claim one job and connect for it (its error if unreachable)
        try:
            return len(self.out) < max(1, self.stream.slots())
        except Exception as exc:  # the scheduler went away
            self._lose_everything(exc)
            return False

    def _send_one(self) -> bool:
        """Claim a job and send it to the cluster (or record its error); ``False`` when none waits."""
        job = jobqueue.claim(self.factory, lease_seconds=self.settings.lease_seconds)
        if job is None:
            return False
        self.leases.hold(job)
        submission = load_submission(self.factory, job)
        flight = _Flight(job, submission, self.storage.upload_path(submission.sha256))
        try:
            flight = self._prepare(flight)
        except Exception as exc:  # the engine's failure: retried, shown to the instructor
            self._record(flight, self._error(flight, exc))
            if not self.stream.connected:
                self.stream.close()
            return True
        self._submit(flight)
        return True

    def _submit(self, flight: _Flight) -> Any:
        """Send a prepared flight's grading; record its error when it cannot go out."""
        try:
            future = self.stream.submit(flight.slots, flight.notebook.read_bytes(),
                                        flight.notebook.name, flight.submission.user_id)
        except Exception as exc:  # the engine's failure: retried, shown to the instructor
            self._record(flight, self._error(flight, exc))
            if not self.stream.connected:
                self.stream.close()
            return None
        if self.out:
            self.out = {f: replace(other, shared=True) for f, other in self.out.items()}
        self.out[future] = replace(flight, shared=bool(self.out))
        return future

    def _send_suspect(self) -> None:
        """Send the next suspect alone, with a whole new time budget."""
        flight = self._suspects.popleft()
        assert flight.assignment is not None and flight.options is not None
        deadline = _deadline(flight.assignment, flight.options)
        flight = replace(flight, deadline=deadline, shared=False)
        self.leases.hold(flight.job, deadline)
        self._lone = self._submit(flight)

    def _prepare(self, flight: _Flight) -> _Flight:
        if flight.job.tries > self.course.max_tries:  # the dispatcher died this many times with it out
            raise EngineError(f"the dispatcher stopped {flight.job.tries - 1} times while this "
                              "submission was out on the Dask cluster")
        policy = self.course.assignment(flight.submission.assignment)
        if policy is None:
            raise LookupError(f"assignment {flight.submission.assignment!r} is no longer in the "
                              "course file")
        assignment = load_assignment(policy.spec)
        options = GradingOptions(public_only=policy.public_only)
        deadline = _deadline(assignment, options)
        self.leases.hold(flight.job, deadline)
        flight = replace(flight, assignment=assignment, options=options, deadline=deadline)
        return replace(flight, slots=self.stream.slots_for(assignment, options))

    def _collect(self, timeout: float) -> None:
        """Record the gradings that came back within ``timeout``."""
        try:
            done = self.stream.finished(list(self.out), timeout)
        except Exception as exc:  # the client lost the scheduler
            self._lose_everything(exc)
            return
        for future in done:
            flight = self.out.pop(future)
            if flight.shared and load_dask_backend().killed_worker(future):
                log.info("job %s lost its workers beside other gradings; it is sent again alone",
                         flight.job.job_id)
                self.leases.hold(flight.job)  # renewed while it waits for the others to come back
                self._suspects.append(flight)
            else:
                self._record(flight, self._result(flight, future))
        if not done:
            self._fail_refused()
        self._fail_overdue()
        self.stream.retire_unused({f.slots for f in (*self.out.values(), *self._suspects)})

    def _result(self, flight: _Flight, future: Any) -> SubmissionResult:
        """The result the cluster sent, its files written into the job's folder; or an error."""
        dask = load_dask_backend()
        assert flight.assignment is not None and flight.options is not None
        try:
            result = dask.payload_files(self._folder(flight), dask.task_payload(future),
                                        f"job {flight.job.job_id}")
        except Exception as exc:
            return self._error(flight, exc)
        key = client_key(flight.notebook, flight.assignment, flight.options)
        return replace(result, id=flight.submission.user_id, source=str(flight.notebook),
                       key=key if result.outcome != "error" else "")

    def _fail_refused(self) -> None:
        """While no worker grades, fail the jobs out when every connected worker refused their slots."""
        if time.monotonic() - self._checked < REFUSAL_CHECK_SECONDS:
            return
        self._checked = time.monotonic()
        try:
            if self.stream.slots() > 0:
                return
            refused = {name: self.stream.refusal(name) for name in {f.slots for f in self.out.values()}}
        except Exception as exc:
            self._lose_everything(exc)
            return
        for future, flight in list(self.out.items()):
            if refused.get(flight.slots):
                future.cancel()
                del self.out[future]
                self._record(flight, self._error(flight, refused[flight.slots]))

    def _fail_overdue(self) -> None:
        """A grading out past its whole budget (a stuck Dask worker) gets an "error" result and
        is retried under ``max_tries``; its lease is no longer renewed."""
        now = time.monotonic()
        for future, flight in list(self.out.items()):
            if flight.deadline is not None and now >= flight.deadline:
                future.cancel()
                del self.out[future]
                self._record(flight, self._error(flight, EngineError(
                    "the grading ran past its whole time budget on the Dask cluster (a worker "
                    "that stopped answering); it is graded again")))

    def _lose_everything(self, exc: BaseException) -> None:
        """The connection failed: every job out or waiting to go out again gets an "error"
        result; the next job connects anew."""
        out, self.out = [*self.out.values(), *self._suspects], {}
        self._suspects.clear()
        for flight in out:
            self._record(flight, self._error(flight, exc))
        try:
            self.stream.close()
        except Exception as problem:  # closing a broken connection must not stop the dispatcher
            log.warning("closing the Dask client failed: %s", problem)

    def _error(self, flight: _Flight, exc: BaseException | str) -> SubmissionResult:
        if isinstance(exc, str):
            exc = EngineError(exc)
        if flight.slots and not any(f.slots == flight.slots for f in self.out.values()):
            self.stream.forget(flight.slots)  # fresh slots for the retry, as a local grader drops its Grader
        if flight.assignment is None:
            return engine_error(flight.submission, flight.notebook, exc)
        return error_result(flight.assignment, flight.notebook, flight.submission.user_id, exc)

    def _folder(self, flight: _Flight) -> Path:
        return self.storage.result_dir(flight.job.job_id, flight.job.claim)

    def _record(self, flight: _Flight, result: SubmissionResult) -> None:
        """Write ``results.json`` and the feedback page as a local grader does; finish the job."""
        folder = self._folder(flight)
        write_submission(folder, result, title=flight.title)
        jobqueue.finish(self.factory, flight.job, result, str(folder.relative_to(self.storage.root)),
                        worker=f"{self.name} (dask)", max_tries=self.course.max_tries)
        self.leases.release(flight.job)
        tell_graded(self.graded, flight.job.submission_id)


def dispatcher_main(settings: GraderSettings, stop: Any, name: str, parent: int,
                    wake: Any = None, graded: Any = None) -> None:
    """The loop of the dispatcher process (started through :func:`autograder.service.pool.grader_entry`)."""
    dispatcher = Dispatcher(settings, name)
    dispatcher.graded = graded
    dispatcher.run(stop, parent, wake)
