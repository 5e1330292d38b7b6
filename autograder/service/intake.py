"""Accepting an upload: every check first, then one transaction (store, submission, job).

A rejected upload (too large, not a notebook, closed assignment, too many this
hour) gets a clear message and leaves nothing behind.
"""

from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from autograder.engine.assignment import load_assignment
from autograder.engine.identify import identify
from autograder.engine.notebook import Notebook, parse_notebook
from autograder.errors import AssignmentError, NotebookError, UploadRejected
from autograder.service import jobqueue
from autograder.service.course import AssignmentPolicy, Course
from autograder.service.models import Submission, User, utcnow
from autograder.service.standing import deadline_for
from autograder.service.storage import Storage


def check_notebook(data: bytes, max_bytes: int, filename: str = "") -> Notebook:
    """The notebook in ``data``; :class:`UploadRejected` unless the engine can read it."""
    if len(data) > max_bytes:
        raise UploadRejected(f"The file is {len(data) / 1e6:.1f} MB; uploads may be at most "
                             f"{max_bytes / 1e6:.1f} MB. Clear the notebook's outputs "
                             "(Kernel > Restart & Clear Output) and upload it again.", status=413)
    if not data.strip():
        raise UploadRejected("The file is empty; upload your .ipynb notebook.")
    try:
        return parse_notebook(data, path=Path(filename or "upload.ipynb").name)
    except NotebookError as exc:
        raise UploadRejected(f"This is not a notebook the grader can read: {exc}",
                             status=422) from None


def precheck(factory: sessionmaker[Session], course: Course, *, user_id: str, assignment: str,
             now: dt.datetime | None = None) -> AssignmentPolicy:
    """Refuse an upload the assignment or the hourly limit would refuse, before it is read.

    The service calls this right after signing the user in, so an upload over the
    limit costs one database read, not the reading and parsing of its body.
    """
    policy = course.assignment(assignment)
    if policy is None:
        raise UploadRejected(f"There is no assignment {assignment!r} in this course.", status=404)
    now = now or utcnow()
    with factory() as session:
        _check_open(session, policy, user_id, now)
        _check_rate(session, course, user_id, assignment, now)
    return policy


def check_assignment(data: bytes | Notebook, policy: AssignmentPolicy, filename: str) -> None:
    """Raise :class:`UploadRejected` when ``data`` is another assignment's notebook.

    A notebook of another assignment would be graded as a zero that nobody asked
    for (:mod:`autograder.engine.identify` says whose it is).
    """
    try:
        assignment = load_assignment(policy.spec)
    except AssignmentError:  # the grader reports a broken assignment with the submission
        return
    notebook = (data if isinstance(data, Notebook) else
                parse_notebook(data, path=Path(filename or "notebook.ipynb").name))
    problem = identify(notebook, assignment).problem
    if problem:
        raise UploadRejected(f"This upload was not accepted: {problem[0].upper()}{problem[1:]} "
                             "Nothing was stored.", status=422)


def accept(factory: sessionmaker[Session], storage: Storage, course: Course, *, user_id: str,
           assignment: str, filename: str, data: bytes,
           now: dt.datetime | None = None) -> Submission:
    """Check an upload and queue it; raise :class:`UploadRejected` with the reason otherwise."""
    if len(data) > course.max_upload_bytes:  # before parsing anything
        check_notebook(data, course.max_upload_bytes)
    now = now or utcnow()
    policy = precheck(factory, course, user_id=user_id, assignment=assignment, now=now)
    notebook = check_notebook(data, course.max_upload_bytes, filename)  # parsed once
    check_assignment(notebook, policy, filename)
    with factory.begin() as session:
        session.execute(select(User).where(User.id == user_id).with_for_update()).scalar_one()
        deadline = _check_open(session, policy, user_id, now)
        _check_rate(session, course, user_id, assignment, now)
        sha = storage.store(data)
        late = policy.late_days(now, deadline)
        submission = Submission(user_id=user_id, assignment=assignment, sha256=sha,
                                filename=Path(filename or "notebook.ipynb").name[:256],
                                submitted_at=now, late_days=late, penalty=policy.penalty(late),
                                status="queued")
        session.add(submission)
        session.flush()
        jobqueue.enqueue(session, submission.id)
    return submission


def _check_open(session: Session, policy: AssignmentPolicy, user_id: str,
                now: dt.datetime) -> dt.datetime:
    deadline = deadline_for(session, policy, user_id)
    if now < policy.opens:
        raise UploadRejected(f"{policy.title} opens on {policy.opens:%Y-%m-%d %H:%M} UTC; "
                             "nothing was stored.", status=409)
    closes = policy.closes_for(deadline)
    if now >= closes:
        raise UploadRejected(f"{policy.title} closed on {closes:%Y-%m-%d %H:%M} UTC (deadline "
                             f"{deadline:%Y-%m-%d %H:%M} UTC plus {policy.max_late_days} late "
                             "day(s)); nothing was stored. Ask your instructor for an extension.",
                             status=409)
    return deadline


def _check_rate(session: Session, course: Course, user_id: str, assignment: str,
                now: dt.datetime) -> None:
    hour_ago = now - dt.timedelta(hours=1)
    recent = session.execute(
        select(func.count(), func.min(Submission.submitted_at))
        .where(Submission.user_id == user_id, Submission.assignment == assignment,
               Submission.submitted_at > hour_ago)).one()
    if recent[0] >= course.submissions_per_hour:
        wait = max(1, math.ceil((recent[1] + dt.timedelta(hours=1) - now).total_seconds()))
        raise UploadRejected(
            f"You have submitted {recent[0]} times in the last hour; the limit is "
            f"{course.submissions_per_hour} per hour. Try again in {math.ceil(wait / 60)} minute(s).",
            status=429, retry_after=wait)
