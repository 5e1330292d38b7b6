"""The grading queue, kept in the database: claim with a lease, finish exactly once.

A job is claimed by one atomic statement that also takes jobs whose lease ran
out (their grader died): ``UPDATE ... WHERE id = (SELECT ... LIMIT 1)`` on
SQLite, where the statement holds the write lock, and the same with
``FOR UPDATE SKIP LOCKED`` on PostgreSQL, so concurrent graders never wait on
or take the same row. The grader renews its lease while it works. Finishing
is one transaction guarded by the claim token: a grader whose lease was taken
over cannot commit, and the ``gradings`` ledger has one row per job at most.

Idle graders look for work every ``poll_seconds``; a job queued by this process
also wakes them at once (:func:`wake_on_enqueue`, set by ``autograder serve`` to its
grading processes' event), once its transaction has committed.
"""

from __future__ import annotations

import datetime as dt
import json
import secrets
from collections.abc import Callable
from dataclasses import dataclass

from sqlalchemy import event, select, text, update
from sqlalchemy.orm import Session, sessionmaker

from autograder.results.model import SubmissionResult
from autograder.service.lti.outbox import note_graded
from autograder.service.models import Grading, Job, Submission, utcnow

#: seconds a claim lasts without renewal; a grader renews it every third of that
from autograder.service.settings import LEASE_SECONDS


@dataclass(frozen=True)
class Claimed:
    """A job this grader holds: grade ``submission_id`` and finish with ``claim``."""

    job_id: int
    submission_id: int
    kind: str
    claim: str
    tries: int


_CLAIM = """
UPDATE jobs SET state = 'running', claim = :claim, lease_until = :lease, tries = tries + 1
WHERE id = (
    SELECT id FROM jobs
    WHERE state = 'queued' OR (state = 'running' AND lease_until < :now)
    ORDER BY priority, id LIMIT 1 {lock}
)
RETURNING id, submission_id, kind, tries
"""


def claim(factory: sessionmaker[Session], *, lease_seconds: float = LEASE_SECONDS) -> Claimed | None:
    """Take the oldest waiting (or abandoned) job, or ``None`` when there is none."""
    token = secrets.token_hex(16)
    now = utcnow()
    with factory.begin() as session:
        lock = "FOR UPDATE SKIP LOCKED" if session.bind.dialect.name == "postgresql" else ""
        row = session.execute(text(_CLAIM.format(lock=lock)), {
            "claim": token, "now": now,
            "lease": now + dt.timedelta(seconds=lease_seconds)}).first()
        if row is None:
            return None
        session.execute(update(Submission).where(Submission.id == row.submission_id,
                                                 Submission.status == "queued")
                        .values(status="running"))
    return Claimed(job_id=row.id, submission_id=row.submission_id, kind=row.kind,
                   claim=token, tries=row.tries)


def renew(factory: sessionmaker[Session], job: Claimed, *,
          lease_seconds: float = LEASE_SECONDS) -> bool:
    """Extend the lease; ``False`` when the job is no longer ours."""
    with factory.begin() as session:
        done = session.execute(update(Job).where(Job.id == job.job_id, Job.claim == job.claim,
                                                 Job.state == "running")
                               .values(lease_until=utcnow() + dt.timedelta(seconds=lease_seconds)))
        return bool(done.rowcount)


def finish(factory: sessionmaker[Session], job: Claimed, result: SubmissionResult,
           result_dir: str, *, worker: str, max_tries: int) -> str:
    """Record ``result`` for the job in one transaction; return what happened.

    ``"done"``: the result is the submission's now. ``"retry"``: the engine failed
    (outcome "error") and the job waits for another try. ``"failed"``: it failed
    ``max_tries`` times; the instructor sees it, the student sees no score.
    ``"lost"``: the lease was taken over meanwhile; nothing was written.
    """
    now = utcnow()
    with factory.begin() as session:
        row = session.execute(select(Job).where(Job.id == job.job_id, Job.claim == job.claim,
                                                Job.state == "running").with_for_update()).scalar()
        if row is None:
            return "lost"
        submission = session.get(Submission, job.submission_id)
        assert submission is not None
        if result.outcome == "error" and job.tries < max_tries:
            row.state, row.claim, row.lease_until, row.error = "queued", None, None, result.output
            if submission.status == "running":
                submission.status = "queued"
            return "retry"
        row.state, row.finished_at = ("failed" if result.outcome == "error" else "done"), now
        row.error = result.output if result.outcome == "error" else ""
        session.add(Grading(job_id=job.job_id, submission_id=job.submission_id, worker=worker,
                            outcome=result.outcome, finished_at=now))
        if result.outcome == "error":
            if submission.status != "graded":  # a regrade that failed keeps the old result
                submission.status, submission.outcome = "error", "error"
            return "failed"
        submission.status, submission.outcome = "graded", result.outcome
        submission.score, submission.max_score = result.score, result.max_score
        submission.result_json = json.dumps(result.to_dict())
        submission.result_dir, submission.graded_at = result_dir, now
        note_graded(session, submission)  # the LMS's score, in the same transaction (LTI AGS)
        return "done"


#: called once a transaction that queued a job has committed (see wake_on_enqueue)
_WAKE: list[Callable[[], None]] = []


def wake_on_enqueue(wake: Callable[[], None] | None) -> None:
    """Call ``wake`` (None: nothing) after every commit that queued a job in this process."""
    _WAKE[:] = [wake] if wake is not None else []


def enqueue(session: Session, submission_id: int, *, kind: str = "grade") -> Job:
    job = Job(submission_id=submission_id, kind=kind, priority=0 if kind == "grade" else 1,
              state="queued", tries=0, error="")
    session.add(job)
    if _WAKE:
        if "queued" not in session.info:  # once per session: its commits and rollbacks
            event.listen(session, "after_commit", _wake_graders)
            event.listen(session, "after_rollback", _forget_queued)
        session.info["queued"] = True
    return job


def _wake_graders(session: Session) -> None:
    if session.info.get("queued"):
        session.info["queued"] = False
        for wake in _WAKE:
            wake()


def _forget_queued(session: Session) -> None:
    session.info["queued"] = False
