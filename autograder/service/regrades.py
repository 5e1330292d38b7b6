"""Regrade requests (no web): a thread per request on one check or answer, open or answered.

A student opens a request on a check of one of their graded attempts with a
message; staff answer in the same thread (it becomes "answered"); a student's
new message opens it again.
"""

from __future__ import annotations

import json

from sqlalchemy import select
from sqlalchemy.orm import Session

from autograder.service.manual_models import RegradeMessage, RegradeRequest
from autograder.service.models import Submission, utcnow

MAX_MESSAGE = 4000


def check_names(sub: Submission) -> list[str]:
    """The checks and manually graded answers of an attempt's result, in its order."""
    return [t["name"] for t in json.loads(sub.result_json or "{}").get("tests", [])]


def open_request(session: Session, sub: Submission, check: str, text: str,
                 author: str) -> RegradeRequest:
    request = RegradeRequest(submission_id=sub.id, check=check, status="open", created_at=utcnow())
    session.add(request)
    session.flush()
    session.add(RegradeMessage(request_id=request.id, author=author, staff=False, text=text,
                               created_at=utcnow()))
    return request


def reply(session: Session, request: RegradeRequest, text: str, author: str, *, staff: bool) -> None:
    session.add(RegradeMessage(request_id=request.id, author=author, staff=staff, text=text,
                               created_at=utcnow()))
    request.status = "answered" if staff else "open"


def threads(session: Session, sub_id: int) -> list[tuple[RegradeRequest, list[RegradeMessage]]]:
    """The attempt's requests, oldest first, each with its messages."""
    requests = list(session.scalars(select(RegradeRequest).where(
        RegradeRequest.submission_id == sub_id).order_by(RegradeRequest.id)))
    messages: dict[int, list[RegradeMessage]] = {r.id: [] for r in requests}
    for message in session.scalars(select(RegradeMessage).where(
            RegradeMessage.request_id.in_(list(messages))).order_by(RegradeMessage.id)):
        messages[message.request_id].append(message)
    return [(r, messages[r.id]) for r in requests]


def open_requests(session: Session) -> list[tuple[RegradeRequest, Submission]]:
    return list(session.execute(
        select(RegradeRequest, Submission).join(Submission, RegradeRequest.submission_id == Submission.id)
        .where(RegradeRequest.status == "open").order_by(RegradeRequest.id)).tuples())
