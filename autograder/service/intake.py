"""Accepting an upload: every check first, then one transaction (store, submission, job).

An upload is a notebook or a zip holding the assignment's notebooks (what otter
and Gradescope hand out); a zip is unpacked with the engine's own checks
(:func:`autograder.engine.submission.open_submission`) into a scratch folder that
is removed at once, so a zip the grader would call ungradable is refused here.
A rejected upload (too large, not a notebook, a zip without the notebook,
another assignment's notebook, closed assignment, too many this hour) gets a
clear message and leaves nothing behind.
"""

from __future__ import annotations

import datetime as dt
import math
import os
import tempfile
import threading
from pathlib import Path

from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.identify import identify
from autograder.engine.notebook import Notebook, parse_notebook
from autograder.engine.submission import ZipLimits, open_submission
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


#: the first bytes of a zip's local file header
ZIP_MAGIC = b"PK\x03\x04"


def is_zip_upload(data: bytes, filename: str) -> bool:
    """A zip by its content (a browser may name it anything) or by its name."""
    return data[:4] == ZIP_MAGIC or filename.lower().endswith(".zip")


class _Assignments:
    """The assignments the intake checks uploads against, loaded once each.

    Loading reads the instructor notebook and every check file; an upload needs
    only what it gives. An assignment is loaded again when any file of its folder
    changed (size or modification time), so an instructor's edit is seen by the
    next upload, never a stale copy.
    """

    def __init__(self) -> None:
        self._held: dict[str, tuple[tuple[tuple[str, int, int], ...], Assignment]] = {}
        self._lock = threading.Lock()

    def get(self, spec: str) -> Assignment:
        with self._lock:
            held = self._held.get(spec)
        if held is not None and held[0] == _signature(held[1].root):
            return held[1]
        assignment = load_assignment(spec)
        with self._lock:
            self._held[spec] = (_signature(assignment.root), assignment)
        return assignment


def _signature(root: Path) -> tuple[tuple[str, int, int], ...]:
    found = []
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in ("__pycache__", ".ipynb_checkpoints"))
        for name in sorted(files):
            try:
                info = os.stat(os.path.join(folder, name))
            except OSError:
                continue
            found.append((os.path.join(folder, name), info.st_size, info.st_mtime_ns))
    return tuple(found)


ASSIGNMENTS = _Assignments()


def check_zip(data: bytes, max_bytes: int, policy: AssignmentPolicy) -> None:
    """Raise :class:`UploadRejected` unless the zip ``data`` holds notebooks of ``policy``'s
    assignment that the engine can read; the unpacked files are removed at once."""
    if len(data) > max_bytes:
        check_notebook(data, max_bytes)  # the size message
    try:
        assignment = ASSIGNMENTS.get(policy.spec)
    except AssignmentError:  # the grader reports a broken assignment with the submission
        return
    with tempfile.TemporaryDirectory(prefix="numgrade-upload-") as scratch:
        archive = Path(scratch) / "upload.zip"
        archive.write_bytes(data)
        # what the service unpacks for one upload: at most 20 uploads' worth (the grader,
        # later, applies its own limits, which are wider)
        limits = ZipLimits(max_total_bytes=min(ZipLimits().max_total_bytes, 20 * max_bytes))
        submission = open_submission(archive, assignment.notebooks, scratch=Path(scratch),
                                     limits=limits)
        if submission.problem:
            raise UploadRejected(f"This zip was not accepted: {submission.problem} Nothing was "
                                 "stored.", status=422)
        for name, path in submission.notebooks:
            notebook = check_notebook(path.read_bytes(), max_bytes, name)
            if name == assignment.notebook.name:
                _check_identity(notebook, assignment)


def check_assignment(data: bytes | Notebook, policy: AssignmentPolicy, filename: str) -> None:
    """Raise :class:`UploadRejected` when ``data`` is another assignment's notebook.

    A notebook of another assignment would be graded as a zero that nobody asked
    for (:mod:`autograder.engine.identify` says whose it is).
    """
    try:
        assignment = ASSIGNMENTS.get(policy.spec)
    except AssignmentError:  # the grader reports a broken assignment with the submission
        return
    notebook = (data if isinstance(data, Notebook) else
                parse_notebook(data, path=Path(filename or "notebook.ipynb").name))
    _check_identity(notebook, assignment)


def _check_identity(notebook: Notebook, assignment: Assignment) -> None:
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
    zipped = is_zip_upload(data, filename)
    if zipped:
        check_zip(data, course.max_upload_bytes, policy)
        filename = filename if filename.lower().endswith(".zip") else f"{Path(filename).stem or 'submission'}.zip"
    else:
        notebook = check_notebook(data, course.max_upload_bytes, filename)  # parsed once
        check_assignment(notebook, policy, filename)
    with factory.begin() as session:
        session.execute(select(User).where(User.id == user_id).with_for_update()).scalar_one()
        deadline = _check_open(session, policy, user_id, now)
        _check_rate(session, course, user_id, assignment, now)
        sha = storage.store(data, suffix=".zip" if zipped else ".ipynb")
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
