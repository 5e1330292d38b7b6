"""The JSON API of ``autograder submit`` and the live status page: an attempt as JSON.

Uploads go through the student pages' form route
(:func:`autograder.service.pages_student.submit`), which answers with
:func:`submission_view` to a bearer token or an ``Accept: application/json``.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from fastapi.responses import JSONResponse, Response

from autograder.service import rubrics
from autograder.service.models import Submission
from autograder.service.standing import final_score
from autograder.service.web import MySubmission, ServiceState

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
def submission_api(mine: MySubmission, svc: ServiceState) -> Response:
    with svc.factory() as session:
        raw = rubrics.load(session, [mine.sub]).raw_score(mine.sub)
    return JSONResponse(submission_view(mine.sub, raw))
