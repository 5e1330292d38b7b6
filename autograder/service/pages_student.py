"""The student pages: signing in and out, assignments, uploading, an attempt and its feedback.

Every attempt is looked up through the signed-in user
(:func:`~autograder.service.web.my_submission`), so another student's id
answers the same 404 as an id that does not exist.
"""

from __future__ import annotations

import datetime as dt
import secrets
import subprocess
from html import escape

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from autograder.errors import UploadRejected, UsageError
from autograder.service import auth
from autograder.service.api_routes import submission_view
from autograder.service.course import AssignmentPolicy
from autograder.service.intake import accept, precheck
from autograder.service.models import Submission, utcnow
from autograder.service.pages_review import people_context
from autograder.service.released import released_notebook, students_notebook
from autograder.service.standing import standing, time_left
from autograder.service.web import (
    LOGIN_COOKIE,
    SESSION_COOKIE,
    Assignment,
    MaybeSignedIn,
    MySubmission,
    Service,
    ServiceState,
    SignedIn,
    Who,
    check_csrf,
    client_address,
    safe_next,
    upload_form,
    wait_message,
    wants_json,
)

router = APIRouter()


# -- signing in ------------------------------------------------------------------------

@router.get("/")
def home(who: MaybeSignedIn) -> Response:
    if who is None:
        return RedirectResponse("/login", status_code=303)
    return RedirectResponse("/instructor" if who.staff else "/assignments", status_code=303)


@router.get("/login")
def login_page(svc: ServiceState, next: str = "/") -> Response:
    nonce = secrets.token_urlsafe(24)
    response = svc.page("login.html.j2", None, csrf=nonce, next=safe_next(next), error="")
    response.set_cookie(LOGIN_COOKIE, nonce, httponly=True, samesite="strict", path="/login")
    return response


def _open_session(svc: Service, token: str, address: str) -> str | int:
    """A new session cookie for the holder of ``token``; for a wrong token, the seconds
    ``address`` must now wait (0: it may try again at once)."""
    with svc.factory.begin() as session:
        user = auth.user_for_token(session, token)
        if user is not None:
            auth.end_expired_sessions(session, lifetime=svc.course.session_lifetime)
            return auth.open_session(session, user)
    return svc.wrong_token(address)


def _login_page(svc: Service, nonce: str, target: str, *, status: int, error: str,
                wait: int = 0) -> Response:
    response = svc.page("login.html.j2", None, status=status, csrf=nonce, next=target, error=error)
    if wait:
        response.headers["Retry-After"] = str(wait)
    return response


@router.post("/login")
async def login(request: Request, svc: ServiceState) -> Response:
    address = client_address(request)
    nonce = request.cookies.get(LOGIN_COOKIE) or ""
    wait = await run_in_threadpool(svc.sign_in_wait, address)  # before reading the form
    if wait:
        return _login_page(svc, nonce, "/", status=429, error=wait_message(wait), wait=wait)
    form = await request.form(max_files=0, max_fields=10, max_part_size=4096)
    if not nonce or not auth.same_secret(str(form.get("csrf", "")), nonce):
        raise HTTPException(403, "The sign-in form is out of date; reload it and try again.")
    token = str(form.get("token", "")).strip()
    target = safe_next(str(form.get("next", "/")))
    cookie = await run_in_threadpool(_open_session, svc, token, address)
    if not isinstance(cookie, str):
        if cookie:
            return _login_page(svc, nonce, target, status=429, error=wait_message(cookie), wait=cookie)
        return _login_page(svc, nonce, target, status=401,
                           error="That access token is not valid. Copy it again from the "
                                 "message your instructor sent.")
    response = RedirectResponse(target, status_code=303)
    response.set_cookie(SESSION_COOKIE, cookie, httponly=True, samesite="lax", path="/",
                        max_age=int(svc.course.session_lifetime.total_seconds()))
    response.delete_cookie(LOGIN_COOKIE, path="/login")
    return response


def _close_session(factory: sessionmaker[Session], cookie: str | None) -> None:
    with factory.begin() as session:
        auth.close_session(session, cookie)


@router.post("/logout")
async def logout(request: Request, who: SignedIn, svc: ServiceState) -> Response:
    check_csrf(who, await request.form(max_fields=5), request)
    await run_in_threadpool(_close_session, svc.factory, request.cookies.get(SESSION_COOKIE))
    response = RedirectResponse("/login", status_code=303)
    response.delete_cookie(SESSION_COOKIE, path="/")
    return response


# -- assignments and uploads -------------------------------------------------------------

def _amount(seconds: float) -> str:
    """"3 days", "2 hours", "5 minutes", "less than a minute" (rounded down)."""
    for size, unit in ((86400, "day"), (3600, "hour"), (60, "minute")):
        if seconds >= size:
            count = int(seconds // size)
            return f"{count} {unit}{'s' if count > 1 else ''}"
    return "less than a minute"


def deadline_words(deadline: dt.datetime, now: dt.datetime) -> str:
    """"in 3 days" before ``deadline``, "passed 2 hours ago" after it."""
    seconds = (deadline - now).total_seconds()
    return f"in {_amount(seconds)}" if seconds > 0 else f"passed {_amount(-seconds)} ago"


@router.get("/assignments")
def assignments(who: SignedIn, svc: ServiceState) -> Response:
    now = utcnow()
    with svc.factory() as session:
        rows = [standing(session, p, who.id) for p in svc.course.assignments]
    return svc.page("assignments.html.j2", who, rows=rows, left=lambda t: time_left(t, now))


def _assignment_page(svc: Service, who: Who, policy: AssignmentPolicy, *, status: int = 200,
                     error: str = "") -> Response:
    """One assignment's page: the student's standing, the upload form and ``error``."""
    now = utcnow()
    with svc.factory() as session:
        stand = standing(session, policy, who.id)
    return svc.page("assignment.html.j2", who, status=status, s=stand, error=error,
                    final_score=stand.final, left=deadline_words(stand.deadline, now),
                    is_open=stand.is_open(now), max_bytes=svc.course.max_upload_bytes)


@router.get("/assignments/{name}")
def assignment_page(who: SignedIn, policy: Assignment, svc: ServiceState) -> Response:
    return _assignment_page(svc, who, policy)


@router.post("/assignments/{name}/submissions")
async def submit(request: Request, name: str, who: SignedIn, policy: Assignment,
                 svc: ServiceState) -> Response:
    try:
        # the assignment's dates and the hourly limit first: a refused upload is never read
        await run_in_threadpool(precheck, svc.factory, svc.course, user_id=who.id, assignment=name)
        form = await upload_form(request, svc)
        check_csrf(who, form, request)
        upload = form.get("notebook")
        if upload is None or isinstance(upload, str):
            raise UploadRejected("Choose your .ipynb notebook (or a zip holding it) to upload.")
        data = await upload.read(svc.course.max_upload_bytes + 1)
        sub = await run_in_threadpool(accept, svc.factory, svc.storage, svc.course, user_id=who.id,
                                      assignment=name, filename=upload.filename or "", data=data)
    except UploadRejected as exc:
        return await run_in_threadpool(_rejected, request, svc, who, policy, exc)
    if wants_json(request, who):
        return JSONResponse(submission_view(sub), status_code=201)
    return RedirectResponse(f"/submissions/{sub.id}", status_code=303)


@router.get("/assignments/{name}/notebook")
async def released(who: SignedIn, policy: Assignment, svc: ServiceState) -> Response:
    """The released notebook (solutions and hidden checks cut out by ``autograder release``),
    for students once the assignment opens."""
    if not who.staff and utcnow() < policy.opens:
        raise HTTPException(403, f"{policy.title} opens {policy.opens:%Y-%m-%d %H:%M} UTC; "
                                 "its notebook can be downloaded from then on.")
    try:
        path = await run_in_threadpool(released_notebook, policy, svc.course.data_dir)
        own = None if who.staff else await run_in_threadpool(
            students_notebook, policy, path, who.id)
    except LookupError as exc:  # not on the roster of variants
        raise HTTPException(403, str(exc)) from None
    except (UsageError, subprocess.TimeoutExpired) as exc:
        raise HTTPException(503, f"{exc} Tell your instructor; try again later.") from None
    if own is not None:  # a variants assignment: this student's own parameters
        return Response(own, media_type="application/x-ipynb+json", headers={
            "Content-Disposition": f'attachment; filename="{path.name}"'})
    return FileResponse(path, media_type="application/x-ipynb+json", filename=path.name)


def _rejected(request: Request, svc: Service, who: Who, policy: AssignmentPolicy,
              exc: UploadRejected) -> Response:
    headers = {"Retry-After": str(exc.retry_after)} if exc.retry_after else {}
    if wants_json(request, who):
        return JSONResponse({"error": str(exc)}, status_code=exc.status, headers=headers)
    response = _assignment_page(svc, who, policy, status=exc.status, error=str(exc))
    response.headers.update(headers)
    return response


# -- an attempt ---------------------------------------------------------------------------

def attempt_number(session: Session, sub: Submission) -> int:
    """The student's count of uploads to this assignment up to ``sub``: 1 is their first.

    Computed from the order of upload (ids grow with time), never shown as the
    database id, which counts everyone's uploads.
    """
    return int(session.scalar(select(func.count()).select_from(Submission).where(
        Submission.user_id == sub.user_id, Submission.assignment == sub.assignment,
        Submission.id <= sub.id)) or 0)


@router.get("/submissions/{sub_id}")
def submission_page(mine: MySubmission, svc: ServiceState) -> Response:
    policy = svc.policy(mine.sub.assignment)
    with svc.factory() as session:  # released manual grading, overrides, regrade requests
        number = attempt_number(session, mine.sub)
        people = people_context(session, mine.sub, staff=False)
    return svc.page("submission.html.j2", mine.who, sub=mine.sub,
                    view=submission_view(mine.sub, people["raw"]), policy=policy, number=number,
                    **people)


def with_way_back(page: Response, href: str, text: str) -> Response:
    """``page`` (a feedback or summary page the service did not write itself) with a link
    back at the top of its ``<main>``; the page's own text is escaped, so the first
    ``<main>`` is the template's."""
    link = f'<main>\n<nav aria-label="Back"><p><a href="{escape(href)}">{escape(text)}</a></p></nav>'
    body = bytes(page.body).decode("utf-8").replace("<main>", link, 1)
    return HTMLResponse(body, status_code=page.status_code, headers={
        k: v for k, v in page.headers.items() if k.lower() != "content-length"})


@router.get("/submissions/{sub_id}/feedback")
def feedback(mine: MySubmission, svc: ServiceState) -> Response:
    with svc.factory() as session:
        number = attempt_number(session, mine.sub)
    return with_way_back(svc.feedback_file(mine.sub), f"/submissions/{mine.sub.id}",
                         f"Back to attempt {number}")
