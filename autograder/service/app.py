"""The web application: student pages, instructor pages, and the JSON API of ``autograder submit``.

Pages are Jinja2 templates (autoescaped) with one small script for the live
status and drag-and-drop; everything is served by the service (no CDN). Feedback
and summary pages contain text written by students, so they are served with
``Content-Security-Policy: sandbox`` and no script: they run in an opaque origin
and cannot read or act on the service. Every object is looked up through the
signed-in user, so changing an id in a URL finds nothing that is not theirs
(the answer is the same 404 as for an id that does not exist).
"""

from __future__ import annotations

import datetime as dt
import functools
import hashlib
import hmac
import secrets
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable
from urllib.parse import quote, urlsplit

import jinja2
from fastapi import FastAPI, HTTPException, Request
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from autograder.errors import UploadRejected
from autograder.results.feedback import FEEDBACK_NAME
from autograder.results.summary import render_summary, summarise
from autograder.service import auth, gradebook, jobqueue
from autograder.service.course import AssignmentPolicy, Course
from autograder.service.intake import accept
from autograder.service.models import Extension, Job, Submission, User, utcnow
from autograder.service.standing import class_standings, final_score, standing, time_left
from autograder.service.storage import Storage

HERE = Path(__file__).resolve().parent
SESSION_COOKIE = "ag_session"
LOGIN_COOKIE = "ag_login"
PAGE_CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
            "connect-src 'self'; form-action 'self'; frame-ancestors 'none'; base-uri 'none'")
#: student-written text: an opaque origin, no script at all, inline styles and data: pictures only
SANDBOX_CSP = ("sandbox; default-src 'none'; style-src 'unsafe-inline'; img-src data:; "
               "frame-ancestors 'none'; base-uri 'none'; form-action 'none'")


@functools.cache
def _templates() -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(HERE / "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined)
    env.filters["when"] = lambda v: "" if v is None else f"{v:%Y-%m-%d %H:%M} UTC"
    env.filters["num"] = lambda v: "–" if v is None else f"{v:g}"
    return env


@dataclass(frozen=True)
class Who:
    """The signed-in user of a request and how they signed in."""

    id: str
    role: str
    csrf: str
    via: str  # cookie | bearer | proxy

    @property
    def staff(self) -> bool:
        return self.role in auth.STAFF


class Service:
    """The state the routes share (immutable after start-up)."""

    def __init__(self, course: Course, factory: sessionmaker[Session], storage: Storage,
                 secret: bytes) -> None:
        self.course, self.factory, self.storage, self.secret = course, factory, storage, secret

    def page(self, name: str, who: Who | None, status: int = 200, **context: Any) -> HTMLResponse:
        html = _templates().get_template(name).render(
            who=who, course=self.course, now=utcnow(), **context)
        return HTMLResponse(html, status_code=status, headers={"Content-Security-Policy": PAGE_CSP})

    def proxy_csrf(self, user_id: str) -> str:
        return hmac.new(self.secret, f"csrf:{user_id}".encode(), hashlib.sha256).hexdigest()

    def who(self, request: Request) -> Who | None:
        with self.factory() as session:
            header = self.course.trusted_header
            client = request.client.host if request.client else ""
            if header and client in self.course.trusted_proxies and request.headers.get(header):
                user = session.get(User, request.headers[header].strip())
                return None if user is None else Who(user.id, user.role,
                                                      self.proxy_csrf(user.id), "proxy")
            bearer = request.headers.get("authorization", "")
            if bearer.lower().startswith("bearer "):
                user = auth.user_for_token(session, bearer[7:].strip())
                return None if user is None else Who(user.id, user.role, "", "bearer")
            signed = auth.find_session(session, request.cookies.get(SESSION_COOKIE))
            return None if signed is None else Who(signed.user_id, signed.role, signed.csrf, "cookie")

    def policy(self, name: str) -> AssignmentPolicy:
        policy = self.course.assignment(name)
        if policy is None:
            raise HTTPException(404, f"There is no assignment {name!r} in this course.")
        return policy

    def submission(self, session: Session, who: Who, sub_id: int) -> Submission:
        """The submission if it is the user's own (staff: any), else 404."""
        sub = session.get(Submission, sub_id)
        if sub is None or (sub.user_id != who.id and not who.staff):
            raise HTTPException(404, "There is no such submission among yours.")
        return sub


class NeedSignIn(Exception):
    pass


def _wants_json(request: Request, who: Who | None) -> bool:
    return (who is not None and who.via == "bearer") or \
        "application/json" in request.headers.get("accept", "")


async def _form(request: Request, svc: Service) -> Any:
    limit = svc.course.max_upload_bytes + 256 * 1024
    length = request.headers.get("content-length")
    if length is not None and length.isdigit() and int(length) > limit:
        raise UploadRejected(f"The upload is larger than {svc.course.max_upload_bytes / 1e6:.1f} MB; "
                             "nothing was stored.", status=413)
    return await request.form(max_files=1, max_fields=20)


def _check_csrf(who: Who, form: Any, request: Request) -> None:
    if who.via == "bearer":
        return  # no cookie involved: another site cannot make the browser send a token
    given = form.get("csrf") if form is not None else None
    given = given or request.headers.get("x-csrf-token")
    if not isinstance(given, str) or not auth.same_secret(given, who.csrf):
        raise HTTPException(403, "This form is out of date or was not sent by this site; "
                                 "reload the page and try again.")


def submission_view(sub: Submission) -> dict[str, Any]:
    """What the live status and ``autograder submit`` read about a submission."""
    score = final_score(sub)
    return {
        "id": sub.id, "assignment": sub.assignment, "status": sub.status,
        "outcome": sub.outcome, "submitted_at": sub.submitted_at.isoformat() + "Z",
        "late_days": sub.late_days, "penalty": sub.penalty,
        "raw_score": sub.score if sub.status == "graded" else None,
        "score": score, "max_score": sub.max_score if sub.status == "graded" else None,
        "url": f"/submissions/{sub.id}",
        "feedback_url": f"/submissions/{sub.id}/feedback" if sub.status == "graded" else None,
        "message": ("The grader could not grade this attempt; your instructor has been told. "
                    "It is not a zero." if sub.status == "error" else ""),
    }


def create_app(course: Course, factory: sessionmaker[Session], *, secret: bytes | None = None
               ) -> FastAPI:
    """The ASGI application for ``course`` over the database behind ``factory``."""
    svc = Service(course, factory, Storage(course.data_dir), secret or secrets.token_bytes(32))
    app = FastAPI(title=f"numgrade: {course.name}", docs_url=None, redoc_url=None, openapi_url=None)
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")
    app.state.service = svc

    @app.middleware("http")
    async def headers(request: Request, call_next: Callable[..., Any]) -> Response:
        response = await call_next(request)
        response.headers.setdefault("X-Content-Type-Options", "nosniff")
        response.headers.setdefault("Referrer-Policy", "same-origin")
        response.headers.setdefault("X-Frame-Options", "DENY")
        if request.url.path.startswith(("/submissions", "/instructor", "/api", "/assignments")):
            response.headers.setdefault("Cache-Control", "no-store")
        return response

    @app.exception_handler(NeedSignIn)
    async def need_sign_in(request: Request, exc: NeedSignIn) -> Response:
        if request.url.path.startswith("/api") or "application/json" in request.headers.get("accept", ""):
            return JSONResponse({"error": "Sign in first: send 'Authorization: Bearer TOKEN' "
                                          "with your access token."}, status_code=401)
        target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
        return RedirectResponse(f"/login?next={quote(target)}", status_code=303)

    @app.exception_handler(HTTPException)
    async def http_error(request: Request, exc: HTTPException) -> Response:
        if request.url.path.startswith("/api") or "application/json" in request.headers.get("accept", ""):
            return JSONResponse({"error": exc.detail}, status_code=exc.status_code)
        who = await run_in_threadpool(svc.who, request)
        return svc.page("error.html.j2", who, status=exc.status_code, message=exc.detail)

    def signed_in(request: Request) -> Who:
        who = svc.who(request)
        if who is None:
            raise NeedSignIn()
        return who

    def staff(request: Request, *, instructor: bool = False) -> Who:
        who = signed_in(request)
        if not who.staff or (instructor and who.role != "instructor"):
            raise HTTPException(403, "Only the course's instructors may open this page."
                                if instructor else "Only course staff may open this page.")
        return who

    # -- signing in ------------------------------------------------------------
    @app.get("/")
    def home(request: Request) -> Response:
        who = svc.who(request)
        if who is None:
            return RedirectResponse("/login", status_code=303)
        return RedirectResponse("/instructor" if who.staff else "/assignments", status_code=303)

    @app.get("/login")
    def login_page(request: Request, next: str = "/") -> Response:
        nonce = secrets.token_urlsafe(24)
        response = svc.page("login.html.j2", None, csrf=nonce, next=_safe_next(next), error="")
        response.set_cookie(LOGIN_COOKIE, nonce, httponly=True, samesite="strict", path="/login")
        return response

    @app.post("/login")
    async def login(request: Request) -> Response:
        form = await request.form(max_fields=10)
        nonce = request.cookies.get(LOGIN_COOKIE)
        if not nonce or not auth.same_secret(str(form.get("csrf", "")), nonce):
            raise HTTPException(403, "The sign-in form is out of date; reload it and try again.")
        token = str(form.get("token", "")).strip()
        target = _safe_next(str(form.get("next", "/")))

        def sign_in() -> str | None:
            with factory.begin() as session:
                user = auth.user_for_token(session, token)
                return None if user is None else auth.open_session(session, user)

        cookie = await run_in_threadpool(sign_in)
        if cookie is None:
            return svc.page("login.html.j2", None, status=401, csrf=nonce, next=target,
                            error="That access token is not valid. Copy it again from the "
                                  "message your instructor sent.")
        response = RedirectResponse(target, status_code=303)
        response.set_cookie(SESSION_COOKIE, cookie, httponly=True, samesite="lax", path="/")
        response.delete_cookie(LOGIN_COOKIE, path="/login")
        return response

    @app.post("/logout")
    async def logout(request: Request) -> Response:
        who = await run_in_threadpool(signed_in, request)
        _check_csrf(who, await request.form(max_fields=5), request)

        def close() -> None:
            with factory.begin() as session:
                auth.close_session(session, request.cookies.get(SESSION_COOKIE))

        await run_in_threadpool(close)
        response = RedirectResponse("/login", status_code=303)
        response.delete_cookie(SESSION_COOKIE, path="/")
        return response

    # -- students ----------------------------------------------------------------
    @app.get("/assignments")
    def assignments(request: Request) -> Response:
        who = signed_in(request)
        now = utcnow()
        with factory() as session:
            rows = [standing(session, p, who.id) for p in course.assignments]
        return svc.page("assignments.html.j2", who, rows=rows, left=lambda t: time_left(t, now))

    @app.get("/assignments/{name}")
    def assignment_page(request: Request, name: str) -> Response:
        who = signed_in(request)
        policy = svc.policy(name)
        now = utcnow()
        with factory() as session:
            stand = standing(session, policy, who.id)
        return svc.page("assignment.html.j2", who, s=stand, error="", final_score=final_score,
                        left=time_left(stand.deadline, now), is_open=stand.is_open(now),
                        max_bytes=course.max_upload_bytes)

    @app.post("/assignments/{name}/submissions")
    async def submit(request: Request, name: str) -> Response:
        who = await run_in_threadpool(signed_in, request)
        svc.policy(name)
        try:
            form = await _form(request, svc)
            _check_csrf(who, form, request)
            upload = form.get("notebook")
            if upload is None or isinstance(upload, str):
                raise UploadRejected("Choose your .ipynb notebook to upload.")
            data = await upload.read(course.max_upload_bytes + 1)
            sub = await run_in_threadpool(accept, factory, svc.storage, course, user_id=who.id,
                                          assignment=name, filename=upload.filename or "", data=data)
        except UploadRejected as exc:
            return await run_in_threadpool(_rejected, request, who, name, exc)
        if _wants_json(request, who):
            return JSONResponse(submission_view(sub), status_code=201)
        return RedirectResponse(f"/submissions/{sub.id}", status_code=303)

    def _rejected(request: Request, who: Who, name: str, exc: UploadRejected) -> Response:
        headers = {"Retry-After": str(exc.retry_after)} if exc.retry_after else {}
        if _wants_json(request, who):
            return JSONResponse({"error": str(exc)}, status_code=exc.status, headers=headers)
        now = utcnow()
        with factory() as session:
            stand = standing(session, svc.policy(name), who.id)
        response = svc.page("assignment.html.j2", who, status=exc.status, s=stand, error=str(exc),
                            final_score=final_score, left=time_left(stand.deadline, now),
                            is_open=stand.is_open(now), max_bytes=course.max_upload_bytes)
        response.headers.update(headers)
        return response

    @app.get("/submissions/{sub_id}")
    def submission_page(request: Request, sub_id: int) -> Response:
        who = signed_in(request)
        with factory() as session:
            sub = svc.submission(session, who, sub_id)
            policy = svc.policy(sub.assignment)
        return svc.page("submission.html.j2", who, sub=sub, view=submission_view(sub), policy=policy)

    @app.get("/api/submissions/{sub_id}")
    def submission_api(request: Request, sub_id: int) -> Response:
        who = signed_in(request)
        with factory() as session:
            return JSONResponse(submission_view(svc.submission(session, who, sub_id)))

    @app.get("/submissions/{sub_id}/feedback")
    def feedback(request: Request, sub_id: int) -> Response:
        who = signed_in(request)
        with factory() as session:
            sub = svc.submission(session, who, sub_id)
        return _feedback_file(sub)

    def _feedback_file(sub: Submission) -> Response:
        folder = svc.storage.resolve_result(sub.result_dir) if sub.result_dir else None
        if sub.status != "graded" or folder is None or not (folder / FEEDBACK_NAME).is_file():
            raise HTTPException(404, "This attempt has no feedback yet; it is still being graded.")
        return sandboxed((folder / FEEDBACK_NAME).read_text(encoding="utf-8"))

    # -- instructors and teaching assistants --------------------------------------
    @app.get("/instructor")
    def instructor_home(request: Request) -> Response:
        who = staff(request)
        with factory() as session:
            tables = [(p, class_standings(session, course, p)) for p in course.assignments]
            failed = session.execute(
                select(Job, Submission).join(Submission, Job.submission_id == Submission.id)
                .where(Job.state.in_(("failed",)) | ((Job.state != "done") & (Job.error != "")))
                .order_by(Job.id.desc()).limit(100)).all()
            waiting = dict(session.execute(
                select(Submission.assignment, func.count()).join(Job, Job.submission_id == Submission.id)
                .where(Job.state.in_(("queued", "running"))).group_by(Submission.assignment)).all())
        return svc.page("instructor.html.j2", who, tables=tables, failed=failed, waiting=waiting,
                        final_score=final_score)

    @app.get("/instructor/students/{user_id}")
    def instructor_student(request: Request, user_id: str) -> Response:
        who = staff(request)
        with factory() as session:
            user = session.get(User, user_id)
            if user is None:
                raise HTTPException(404, f"No one with id {user_id!r} is on the roster.")
            rows = [standing(session, p, user.id) for p in course.assignments]
        return svc.page("student.html.j2", who, user=user, rows=rows, final_score=final_score)

    @app.get("/instructor/{name}/summary/")
    def summary(request: Request, name: str) -> Response:
        staff(request)
        policy = svc.policy(name)
        with factory() as session:
            results = gradebook.counted_results(class_standings(session, course, policy))
        return sandboxed(render_summary(summarise(results, assignment=name), title=policy.title))

    @app.get("/instructor/{name}/summary/{user_id}/" + FEEDBACK_NAME)
    def summary_feedback(request: Request, name: str, user_id: str) -> Response:
        staff(request)
        policy = svc.policy(name)
        with factory() as session:
            stand = standing(session, policy, user_id)
        if stand.counted is None:
            raise HTTPException(404, "This student has no graded attempt.")
        return _feedback_file(stand.counted)

    @app.get("/instructor/{name}/export/{kind}")
    def export(request: Request, name: str, kind: str) -> Response:
        staff(request)
        policy = svc.policy(name)
        with factory() as session:
            rows = class_standings(session, course, policy)
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

    @app.post("/instructor/extensions")
    async def extension(request: Request) -> Response:
        who = await run_in_threadpool(staff, request, instructor=True)
        form = await request.form(max_fields=10)
        _check_csrf(who, form, request)
        user_id, name = str(form.get("student", "")), str(form.get("assignment", ""))
        svc.policy(name)
        text = str(form.get("deadline", "")).strip()
        try:
            deadline = dt.datetime.fromisoformat(text) if text else None
        except ValueError:
            raise HTTPException(400, f"Write the new deadline as 2026-10-01T23:59 (UTC); got {text!r}.")
        if deadline is not None and deadline.tzinfo is not None:
            deadline = deadline.astimezone(dt.timezone.utc).replace(tzinfo=None)

        def save() -> None:
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

        await run_in_threadpool(save)
        return RedirectResponse(f"/instructor/students/{quote(user_id)}", status_code=303)

    @app.post("/instructor/{name}/regrade")
    async def regrade(request: Request, name: str) -> Response:
        who = await run_in_threadpool(staff, request, instructor=True)
        _check_csrf(who, await request.form(max_fields=5), request)
        svc.policy(name)

        def queue_all() -> int:
            with factory.begin() as session:
                ids = session.scalars(select(Submission.id).where(
                    Submission.assignment == name, Submission.status.in_(("graded", "error")))).all()
                waiting = set(session.scalars(select(Job.submission_id).where(
                    Job.submission_id.in_(ids), Job.state.in_(("queued", "running")))))
                for sub_id in ids:
                    if sub_id not in waiting:
                        jobqueue.enqueue(session, sub_id, kind="regrade")
                return len(ids) - len(waiting)

        count = await run_in_threadpool(queue_all)
        if _wants_json(request, who):
            return JSONResponse({"queued": count})
        return RedirectResponse(f"/instructor?regrade={count}#{quote(name)}", status_code=303)

    @app.post("/instructor/tokens")
    async def tokens(request: Request) -> Response:
        who = await run_in_threadpool(staff, request, instructor=True)
        form = await request.form(max_fields=5)
        _check_csrf(who, form, request)
        everyone = form.get("scope") == "all"

        def issue() -> str:
            with factory.begin() as session:
                return auth.tokens_csv(auth.issue_tokens(session, everyone=everyone))

        text = await run_in_threadpool(issue)
        return Response(text, media_type="text/csv", headers={
            "Content-Disposition": 'attachment; filename="tokens.csv"'})

    return app


def sandboxed(html: str) -> HTMLResponse:
    """A page holding student-written text: no script, opaque origin."""
    return HTMLResponse(html, headers={"Content-Security-Policy": SANDBOX_CSP,
                                       "X-Content-Type-Options": "nosniff"})


def _safe_next(target: str) -> str:
    """Only a path on this site (never ``//evil`` or ``https://...``)."""
    parts = urlsplit(target)
    if parts.scheme or parts.netloc or not target.startswith("/") or target.startswith("//"):
        return "/"
    return target
