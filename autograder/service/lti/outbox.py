"""Scores to the LMS (LTI AGS): a durable outbox and the sender that empties it.

:func:`note_graded` writes one row per line item of the student's assignment in
the transaction that records the grading (:func:`autograder.service.jobqueue.finish`),
so a result never exists without its row. :class:`ScoreSender`, a thread of
the service process, posts each due row: the score that counts *at sending
time* (late penalty and best/last, as :mod:`~autograder.service.standing`
computes it), so a late row never sends a stale score. A failure (the LMS down,
a non-2xx answer) keeps the row and tries again with exponential backoff; rows
still pending when the service starts are due at once. A row is only marked
sent after the LMS answered 2xx.
"""

from __future__ import annotations

import datetime as dt
import json
import logging
import threading
from typing import Any

from pylti1p3.exception import LtiException, LtiServiceException
from pylti1p3.service_connector import ServiceConnector
from sqlalchemy import select, update
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session, sessionmaker

from autograder.service.course import Course
from autograder.service.lti.adapters import TimedSession
from autograder.service.lti.config import tool_conf
from autograder.service.lti.keys import tool_key
from autograder.service.lti.tables import LtiLink, LtiScore
from autograder.service.models import Submission, utcnow
from autograder.service.standing import final_score, standing

log = logging.getLogger("autograder.service.lti")

SCORE_SCOPE = "https://purl.imsglobal.org/spec/lti-ags/scope/score"
#: seconds between two looks at the outbox, and the longest wait between two tries of a row
POLL_SECONDS = 1.0
MAX_BACKOFF_SECONDS = 300.0


def note_graded(session: Session, submission: Submission) -> int:
    """Queue a score for every line item the student's assignment is linked to; the count."""
    links = session.scalars(select(LtiLink.id).where(LtiLink.user_id == submission.user_id,
                                                     LtiLink.assignment == submission.assignment))
    count = 0
    for link_id in links:
        session.add(LtiScore(link_id=link_id, state="pending", tries=0, next_try_at=utcnow(),
                             last_error=""))
        count += 1
    return count


def backoff(tries: int) -> float:
    """Seconds before try ``tries + 1``: 2, 4, 8, ... at most five minutes."""
    return min(MAX_BACKOFF_SECONDS, 2.0 ** min(tries, 16))


class ScoreSender:
    """Posts the outbox's due rows, one at a time, from one thread of the service process."""

    def __init__(self, course: Course, factory: sessionmaker[Session]) -> None:
        self.course, self.factory = course, factory
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="lti-scores")
        self._connectors: dict[tuple[str, str], ServiceConnector] = {}

    def start(self) -> None:
        with self.factory.begin() as session:  # what a stopped service left: due now
            session.execute(update(LtiScore).where(LtiScore.state == "pending")
                            .values(next_try_at=utcnow()))
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2 * 15.0 + 5)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                busy = self.send_due()
            except SQLAlchemyError as exc:  # the database hiccuped: the rows wait
                log.warning("the LTI outbox could not be read: %s", exc)
                busy = False
            if not busy:
                self._stop.wait(POLL_SECONDS)

    def send_due(self) -> bool:
        """Try every due row once; whether there was any."""
        with self.factory() as session:
            due = session.scalars(select(LtiScore.id).where(
                LtiScore.state == "pending", LtiScore.next_try_at <= utcnow())
                .order_by(LtiScore.id).limit(50)).all()
        for row_id in due:
            if self._stop.is_set():
                break
            self._send(row_id)
        return bool(due)

    def _send(self, row_id: int) -> None:
        with self.factory() as session:
            row = session.get(LtiScore, row_id)
            link = session.get(LtiLink, row.link_id) if row is not None else None
            score = self._score(session, link) if link is not None else None
        if row is None or link is None:
            return
        error = ""
        if score is not None:
            try:
                self._post(link, score)
            except (LtiException, OSError, ValueError, KeyError) as exc:
                error = _describe(exc)
                # the next try gets a fresh access token (this one may have expired)
                self._connectors.pop((link.issuer, link.client_id), None)
        with self.factory.begin() as session:
            row = session.get(LtiScore, row_id)
            if row is None or row.state != "pending":
                return
            if error:
                row.tries += 1
                row.last_error = error[:2000]
                row.next_try_at = utcnow() + dt.timedelta(seconds=backoff(row.tries))
                log.warning("score %s to %s not accepted (try %s): %s", row_id, link.lineitem,
                            row.tries, error)
                return
            row.state, row.sent_at = "sent", utcnow()
            if score is not None:
                row.score_given, row.score_maximum = score["scoreGiven"], score["scoreMaximum"]

    def _score(self, session: Session, link: LtiLink) -> dict[str, Any] | None:
        """The AGS score of the attempt that counts now; ``None`` when none counts yet."""
        policy = self.course.assignment(link.assignment)
        if policy is None:
            return None
        counted = standing(session, policy, link.user_id).counted
        given = final_score(counted) if counted is not None else None
        if counted is None or given is None or not counted.max_score:
            return None
        return {"scoreGiven": given, "scoreMaximum": counted.max_score, "userId": link.sub,
                "activityProgress": "Completed", "gradingProgress": "FullyGraded",
                "timestamp": utcnow().replace(tzinfo=dt.timezone.utc).isoformat()}

    def _post(self, link: LtiLink, score: dict[str, Any]) -> None:
        connector = self._connector(link.issuer, link.client_id)
        base, _, query = link.lineitem.partition("?")
        url = f"{base.rstrip('/')}/scores" + (f"?{query}" if query else "")
        connector.make_service_request([SCORE_SCOPE], url, is_post=True, data=json.dumps(score),
                                       content_type="application/vnd.ims.lis.v1.score+json")

    def _connector(self, issuer: str, client_id: str) -> ServiceConnector:
        """One connector per registration: it keeps the access token between posts."""
        if (issuer, client_id) not in self._connectors:
            registration = tool_conf(self.course, tool_key(self.factory)).find_registration_by_params(
                issuer, client_id)
            self._connectors[(issuer, client_id)] = ServiceConnector(registration, TimedSession())
        return self._connectors[(issuer, client_id)]


def _describe(exc: BaseException) -> str:
    if isinstance(exc, LtiServiceException):
        return f"the LMS answered {exc.response.status_code}: {exc.response.text[:500]}"
    return f"{type(exc).__name__}: {exc}"
