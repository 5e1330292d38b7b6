"""One submission at a time: regrade it, override a score with a reason, regrade requests.

Staff see an attempt's checks with its people's grading; an instructor may
re-queue it or set a check's score or the total, with a reason kept in a
history the student sees. A student asks for a regrade of one check or answer
of their own graded attempt; staff answer in the same thread. Released manual
grading (rubric items and comments) is shown to the student on the attempt's page.
"""

from __future__ import annotations

import math
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import RedirectResponse, Response
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from autograder.service import jobqueue, regrades, rubrics
from autograder.service.manual_models import RegradeRequest
from autograder.service.models import Job, Submission
from autograder.service.pages_grading import small_form
from autograder.service.web import Instructor, MySubmission, Service, ServiceState, StaffMember, Who

router = APIRouter()


def people_context(session: Session, sub: Submission, *, staff: bool) -> dict[str, Any]:
    """What the attempt pages show of people's grading (a student: only what is released)."""
    people = rubrics.load(session, [sub])
    result = people.result(sub, released_only=not staff)
    marks = {q: m for (s, q), m in people.marks.items()
             if s == sub.id and (staff or people.is_released(sub.assignment, q))}
    return {"result": result, "marks": marks, "history": rubrics.history(session, sub.id),
            "threads": regrades.threads(session, sub.id), "checks": regrades.check_names(sub),
            "raw": people.raw_score(sub)}


def _message(form: Any, key: str = "message") -> str:
    text = str(form.get(key, "")).strip()
    if not text:
        raise HTTPException(400, "Write a message saying what should be looked at again; it was empty.")
    if len(text) > regrades.MAX_MESSAGE:
        raise HTTPException(400, f"A message is at most {regrades.MAX_MESSAGE} characters; "
                                 f"got {len(text)}.")
    return text


def _check(sub: Submission, form: Any) -> str:
    check = str(form.get("check", ""))
    if check and check not in regrades.check_names(sub):
        raise HTTPException(400, f"Attempt {sub.id} has no check {check!r}; choose one from the list.")
    return check


# -- staff ---------------------------------------------------------------------------------

def _waiting(session: Session, sub_id: int) -> bool:
    """Whether a grading of the attempt is queued or running."""
    return session.scalar(select(Job.id).where(
        Job.submission_id == sub_id, Job.state.in_(("queued", "running"))).limit(1)) is not None


def _staff_sub(svc: Service, session: Session, who: Who, sub_id: int) -> Submission:
    return svc.submission(session, who, sub_id)


@router.get("/instructor/submissions/{sub_id}")
def staff_submission(sub_id: int, who: StaffMember, svc: ServiceState) -> Response:
    with svc.factory() as session:
        sub = _staff_sub(svc, session, who, sub_id)
        context = people_context(session, sub, staff=True)
        waiting = _waiting(session, sub.id)
    return svc.page("review.html.j2", who, sub=sub, policy=svc.policy(sub.assignment),
                    waiting=waiting, **context)


@router.post("/instructor/submissions/{sub_id}/regrade")
async def regrade_one(request: Request, sub_id: int, who: Instructor, svc: ServiceState) -> Response:
    await small_form(request, who)

    def queue(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            sub = _staff_sub(svc, session, who, sub_id)
            if not _waiting(session, sub.id):  # one grading at a time: a second click changes nothing
                jobqueue.enqueue(session, sub.id, kind="regrade")
    await run_in_threadpool(queue, svc.factory)
    return RedirectResponse(f"/instructor/submissions/{sub_id}", status_code=303)


def _score(form: Any) -> float | None:
    text = str(form.get("score", "")).strip()
    if not text:
        return None  # take the override away
    try:
        value = float(text)
    except ValueError:
        raise HTTPException(400, f"The score must be a number such as 7.5 (empty: take the "
                                 f"override away); got {text!r}.")
    if not math.isfinite(value) or value < 0:
        raise HTTPException(400, f"The score must be a finite number, 0 or more; got {text!r}.")
    return value


@router.post("/instructor/submissions/{sub_id}/override")
async def override(request: Request, sub_id: int, who: Instructor, svc: ServiceState) -> Response:
    form = await small_form(request, who)
    score = _score(form)
    reason = str(form.get("reason", "")).strip()
    if not reason:
        raise HTTPException(400, "Give the reason for the new score; the student reads it.")

    def save(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            sub = _staff_sub(svc, session, who, sub_id)
            if sub.status != "graded":
                raise HTTPException(409, "This attempt is not graded; override a graded attempt.")
            rubrics.add_override(session, sub, _check(sub, form), score, reason[:4000], who.id)
    await run_in_threadpool(save, svc.factory)
    return RedirectResponse(f"/instructor/submissions/{sub_id}", status_code=303)


@router.get("/instructor/regrade-requests")
def staff_requests(who: StaffMember, svc: ServiceState) -> Response:
    with svc.factory() as session:
        rows = regrades.open_requests(session)
    return svc.page("regrade_requests.html.j2", who, rows=rows)


# -- both: a thread ------------------------------------------------------------------------

@router.post("/submissions/{sub_id}/regrade-requests")
async def ask(request: Request, mine: MySubmission, svc: ServiceState) -> Response:
    form = await small_form(request, mine.who)
    text = _message(form)

    def save(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            sub = svc.submission(session, mine.who, mine.sub.id)
            if sub.status != "graded":
                raise HTTPException(409, "Only a graded attempt can be regraded; wait for its score.")
            regrades.open_request(session, sub, _check(sub, form), text, mine.who.id)
    await run_in_threadpool(save, svc.factory)
    return RedirectResponse(f"/submissions/{mine.sub.id}#regrades", status_code=303)


@router.post("/submissions/{sub_id}/regrade-requests/{request_id}")
async def answer(request: Request, request_id: int, mine: MySubmission,
                 svc: ServiceState) -> Response:
    form = await small_form(request, mine.who)
    text = _message(form)

    def save(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            thread = session.get(RegradeRequest, request_id)
            if thread is None or thread.submission_id != mine.sub.id:
                raise HTTPException(404, "There is no such regrade request on this attempt.")
            regrades.reply(session, thread, text, mine.who.id, staff=mine.who.staff)
    await run_in_threadpool(save, svc.factory)
    back = f"/instructor/submissions/{mine.sub.id}" if mine.who.staff else f"/submissions/{mine.sub.id}"
    return RedirectResponse(back + "#regrades", status_code=303)
