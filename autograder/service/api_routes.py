"""The JSON API of ``autograder submit`` and the live status page: an attempt as JSON
(``?wait=S``: once it is graded, see :mod:`autograder.service.waits`).

Uploads go through the student pages' form route
(:func:`autograder.service.pages_student.submit`), which answers with
:func:`submission_view` to a bearer token or an ``Accept: application/json``.
"""

from __future__ import annotations

import asyncio
import time
from typing import Annotated, Any

from fastapi import APIRouter, Query
from fastapi.responses import JSONResponse, Response
from starlette.concurrency import run_in_threadpool

from autograder.service import rubrics
from autograder.service.models import Submission
from autograder.service.standing import final_score
from autograder.service.waits import MAX_WAIT, RECHECK
from autograder.service.web import MySubmission, Service, ServiceState

router = APIRouter()


def submission_view(sub: Submission, raw: float | None = None) -> dict[str, Any]:
    """What the live status and ``autograder submit`` read about a submission;
    ``raw``: its score with people's grading in (:mod:`~autograder.service.rubrics`)."""
    score = final_score(sub, raw)
    return {
        "id": sub.id, "assignment": sub.assignment, "status": sub.status,
        "outcome": sub.outcome, "submitted_at": sub.submitted_at.isoformat() + "Z",
        "late_days": sub.late_days, "penalty": sub.penalty,
        "raw_score": (sub.score if raw is None else raw) if sub.status == "graded" else None,
        "score": score, "max_score": sub.max_score if sub.status == "graded" else None,
        "url": f"/submissions/{sub.id}",
        "feedback_url": f"/submissions/{sub.id}/feedback" if sub.status == "graded" else None,
        "message": ("The grader could not grade this attempt; your instructor has been told. "
                    "It is not a zero." if sub.status == "error" else ""),
    }


@router.get("/api/submissions/{sub_id}")
async def submission_api(mine: MySubmission, svc: ServiceState,
                         wait: Annotated[float, Query(ge=0, le=MAX_WAIT, allow_inf_nan=False)] = 0.0
                         ) -> Response:
    """The attempt as JSON; with ``wait`` (seconds), once it is graded or failed, or when
    ``wait`` has passed (see :mod:`autograder.service.waits`)."""
    sub = mine.sub
    deadline = time.monotonic() + wait
    while sub.status in ("queued", "running") and (left := deadline - time.monotonic()) > 0:
        if svc.waits is not None:
            await svc.waits.wait(sub.id, min(left, RECHECK))
        else:  # no grading processes of ours to tell us: look again now and then
            await asyncio.sleep(min(left, RECHECK / 4))
        sub = await run_in_threadpool(_reload, svc, sub.id)
    return JSONResponse(await run_in_threadpool(_view, svc, sub))


def _reload(svc: Service, sub_id: int) -> Submission:
    with svc.factory() as session:
        sub = session.get(Submission, sub_id)
        assert sub is not None  # submissions are never deleted
        session.expunge(sub)
    return sub


def _view(svc: Service, sub: Submission) -> dict[str, Any]:
    with svc.factory() as session:
        raw = rubrics.load(session, [sub]).raw_score(sub)
    return submission_view(sub, raw)
