"""The instructor pages: the class, a student, summaries, exports, regrades, extensions, tokens.

Teaching assistants may read (the class, summaries, exports); only instructors
may change anything (regrade, extensions, new tokens). The summary holds
student-written text and is served sandboxed like feedback.
"""

from __future__ import annotations

import datetime as dt
from typing import Callable
from urllib.parse import quote

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import JSONResponse, RedirectResponse, Response
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from autograder.results.feedback import FEEDBACK_NAME
from autograder.results.summary import render_summary, summarise
from autograder.service import auth, gradebook, jobqueue
from autograder.service.models import Extension, Job, Submission, User
from autograder.service.pages_student import with_way_back
from autograder.service.standing import class_standings, final_score, standing
from autograder.service.web import (
    Assignment,
    Instructor,
    ServiceState,
    StaffMember,
    check_csrf,
    sandboxed,
    wants_json,
)

router = APIRouter()


# -- reading: teaching assistants and instructors -----------------------------------------

@router.get("/instructor")
def instructor_home(who: StaffMember, svc: ServiceState, regrade: int | None = None,
                    assignment: str = "") -> Response:
    with svc.factory() as session:
        tables = [(p, class_standings(session, svc.course, p)) for p in svc.course.assignments]
        failed = session.execute(
            select(Job, Submission).join(Submission, Job.submission_id == Submission.id)
            .where(Job.state.in_(("failed",)) | ((Job.state != "done") & (Job.error != "")))
            .order_by(Job.id.desc()).limit(100)).all()
        waiting = dict(session.execute(
            select(Submission.assignment, func.count()).join(Job, Job.submission_id == Submission.id)
            .where(Job.state.in_(("queued", "running"))).group_by(Submission.assignment)).all())
    # the confirmation after "Regrade every submission" (the redirect says how many)
    regraded_title = next((p.title for p in svc.course.assignments if p.name == assignment),
                          "the assignment")
    return svc.page("instructor.html.j2", who, tables=tables, failed=failed, waiting=waiting,
                    final_score=final_score, regraded=regrade, regraded_title=regraded_title)


@router.get("/instructor/students/{user_id}")
def instructor_student(user_id: str, who: StaffMember, svc: ServiceState) -> Response:
    with svc.factory() as session:
        user = session.get(User, user_id)
        if user is None:
            raise HTTPException(404, f"No one with id {user_id!r} is on the roster.")
        rows = [standing(session, p, user.id) for p in svc.course.assignments]
    return svc.page("student.html.j2", who, user=user, rows=rows, final_score=final_score)


@router.get("/instructor/{name}/summary/")
def summary(name: str, who: StaffMember, policy: Assignment, svc: ServiceState) -> Response:
    with svc.factory() as session:
        results = gradebook.counted_results(class_standings(session, svc.course, policy))
    page = sandboxed(render_summary(summarise(results, assignment=name), title=policy.title))
    return with_way_back(page, "/instructor", "Back to the class")


@router.get("/instructor/{name}/summary/{user_id}/" + FEEDBACK_NAME)
def summary_feedback(user_id: str, who: StaffMember, policy: Assignment,
                     svc: ServiceState) -> Response:
    with svc.factory() as session:
        stand = standing(session, policy, user_id)
    if stand.counted is None:
        raise HTTPException(404, "This student has no graded attempt.")
    return with_way_back(svc.feedback_file(stand.counted), "../", "Back to the class summary")


@router.get("/instructor/{name}/export/{kind}")
def export(name: str, kind: str, who: StaffMember, policy: Assignment,
           svc: ServiceState) -> Response:
    with svc.factory() as session:
        rows = class_standings(session, svc.course, policy)
    files: dict[str, tuple[Callable[[], str | bytes], str]] = {
        "grades.csv": (lambda: gradebook.grades_csv(rows), "text/csv"),
        "canvas.csv": (lambda: gradebook.canvas_csv(policy, rows), "text/csv"),
        "junit.xml": (lambda: gradebook.junit(policy, rows), "application/xml"),
        "gradescope.zip": (lambda: gradebook.gradescope_zip(rows), "application/zip"),
    }
    if kind not in files:
        raise HTTPException(404, f"Unknown export {kind!r}; choose one of {', '.join(files)}.")
    make, media = files[kind]
    return Response(make(), media_type=media, headers={
        "Content-Disposition": f'attachment; filename="{name}-{kind}"'})


# -- changing: instructors only ----------------------------------------------------------

def _deadline(text: str) -> dt.datetime | None:
    """The new deadline as naive UTC (``None``: take the extension away), else 400."""
    try:
        deadline = dt.datetime.fromisoformat(text) if text else None
    except ValueError:
        raise HTTPException(400, f"Write the new deadline as 2026-10-01T23:59 (UTC); got {text!r}.")
    if deadline is not None and deadline.tzinfo is not None:
        deadline = deadline.astimezone(dt.timezone.utc).replace(tzinfo=None)
    return deadline


def _save_extension(factory: sessionmaker[Session], user_id: str, name: str,
                    deadline: dt.datetime | None) -> None:
    with factory.begin() as session:
        if session.get(User, user_id) is None:
            raise HTTPException(404, f"No one with id {user_id!r} is on the roster.")
        row = session.get(Extension, (user_id, name))
        if deadline is None:
            if row is not None:
                session.delete(row)
        elif row is None:
            session.add(Extension(user_id=user_id, assignment=name, deadline=deadline))
        else:
            row.deadline = deadline


@router.post("/instructor/extensions")
async def extension(request: Request, who: Instructor, svc: ServiceState) -> Response:
    form = await request.form(max_fields=10)
    check_csrf(who, form, request)
    user_id, name = str(form.get("student", "")), str(form.get("assignment", ""))
    svc.policy(name)
    deadline = _deadline(str(form.get("deadline", "")).strip())
    await run_in_threadpool(_save_extension, svc.factory, user_id, name, deadline)
    return RedirectResponse(f"/instructor/students/{quote(user_id)}", status_code=303)


def _queue_regrades(factory: sessionmaker[Session], name: str) -> int:
    """Queue every graded or failed attempt of ``name`` not already waiting; how many."""
    with factory.begin() as session:
        ids = session.scalars(select(Submission.id).where(
            Submission.assignment == name, Submission.status.in_(("graded", "error")))).all()
        waiting = set(session.scalars(select(Job.submission_id).where(
            Job.submission_id.in_(ids), Job.state.in_(("queued", "running")))))
        for sub_id in ids:
            if sub_id not in waiting:
                jobqueue.enqueue(session, sub_id, kind="regrade")
        return len(ids) - len(waiting)


@router.post("/instructor/{name}/regrade")
async def regrade(request: Request, name: str, who: Instructor, svc: ServiceState) -> Response:
    check_csrf(who, await request.form(max_fields=5), request)
    svc.policy(name)  # after the CSRF check, so a forged form is refused whatever name it gives
    count = await run_in_threadpool(_queue_regrades, svc.factory, name)
    if wants_json(request, who):
        return JSONResponse({"queued": count})
    return RedirectResponse(f"/instructor?regrade={count}&assignment={quote(name)}#{quote(name)}",
                            status_code=303)


def _issue_tokens(factory: sessionmaker[Session], everyone: bool) -> str:
    with factory.begin() as session:
        return auth.tokens_csv(auth.issue_tokens(session, everyone=everyone))


@router.post("/instructor/tokens")
async def tokens(request: Request, who: Instructor, svc: ServiceState) -> Response:
    form = await request.form(max_fields=5)
    check_csrf(who, form, request)
    text = await run_in_threadpool(_issue_tokens, svc.factory, form.get("scope") == "all")
    return Response(text, media_type="text/csv", headers={
        "Content-Disposition": 'attachment; filename="tokens.csv"'})
