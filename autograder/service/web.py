"""What the service's routers share: pages, the request's user and course, CSRF, error pages.

The routers (:mod:`~autograder.service.pages_student`,
:mod:`~autograder.service.pages_staff`, :mod:`~autograder.service.api_routes`)
reach the course, the database and the upload store through the
:class:`Service` that :func:`autograder.service.app.create_app` keeps in
``app.state.service``, and the signed-in user through the dependencies below
(``SignedIn``, ``StaffMember``, ``Instructor``, ``MySubmission``). Every page carries
``PAGE_CSP``; pages holding student-written text are :func:`sandboxed`.
"""

from __future__ import annotations

import datetime as dt

import functools
import hashlib
import hmac
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Callable
from urllib.parse import quote, urlsplit

import jinja2
from fastapi import Depends, HTTPException, Request
from fastapi.responses import HTMLResponse, JSONResponse, RedirectResponse, Response
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from autograder.errors import UploadRejected
from autograder.results.feedback import FEEDBACK_NAME, render_feedback
from autograder.results.store import read_result
from autograder.service import auth, rubrics, throttle
from autograder.service.standing import deadline_for
from autograder.service.bounds import RequestTooLarge
from autograder.service.course import AssignmentPolicy, Course
from autograder.service.models import Submission, User, utcnow
from autograder.service.storage import Storage
from autograder.service.waits import Waits

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
                 secret: bytes, waits: Waits | None = None) -> None:
        self.course, self.factory, self.storage, self.secret = course, factory, storage, secret
        #: requests waiting for a grade, woken by the grading processes (None: none of ours)
        self.waits = waits

    def page(self, name: str, who: Who | None, status: int = 200, **context: Any) -> HTMLResponse:
        html = _templates().get_template(name).render(
            who=who, course=self.course, now=utcnow(), **context)
        return HTMLResponse(html, status_code=status, headers={"Content-Security-Policy": PAGE_CSP})

    def proxy_csrf(self, user_id: str) -> str:
        return hmac.new(self.secret, f"csrf:{user_id}".encode(), hashlib.sha256).hexdigest()

    def who(self, request: Request) -> Who | None:
        """The request's user (looked up once per request); 429 while its address is throttled."""
        cached = getattr(request.state, "who", _UNKNOWN)
        if cached is _UNKNOWN:
            cached = self._who(request)
            request.state.who = cached
        return cached

    def _who(self, request: Request) -> Who | None:
        header = self.course.trusted_header
        client = request.client.host if request.client else ""
        bearer = request.headers.get("authorization", "")
        with self.factory() as session:
            if header and client in self.course.trusted_proxies and request.headers.get(header):
                user = session.get(User, request.headers[header].strip())
                return None if user is None else Who(user.id, user.role,
                                                      self.proxy_csrf(user.id), "proxy")
            if not bearer.lower().startswith("bearer "):
                signed = auth.find_session(session, request.cookies.get(SESSION_COOKIE),
                                           lifetime=self.course.session_lifetime)
                return None if signed is None else Who(signed.user_id, signed.role, signed.csrf,
                                                       "cookie")
            address = client_address(request)
            wait = throttle.wait_seconds(session, address)
            if wait:
                raise TooManyWrongTokens(wait)
            user = auth.user_for_token(session, bearer[7:].strip())
            if user is not None:
                return Who(user.id, user.role, "", "bearer")
        self.wrong_token(address)  # its own transaction, after this one (SQLite: one writer)
        return None

    def wrong_token(self, address: str) -> int:
        """Count a wrong access token from ``address``; the seconds it must now wait."""
        with self.factory.begin() as session:
            return throttle.record_failure(session, address)

    def sign_in_wait(self, address: str) -> int:
        with self.factory() as session:
            return throttle.wait_seconds(session, address)

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

    def feedback_file(self, sub: Submission) -> Response:
        """The feedback page of a graded attempt, sandboxed; 404 while it is being graded.

        When people graded it (released manual points, overrides) the page is made
        again from the result with their grading in, else the grader's file is served.
        """
        folder = self.storage.resolve_result(sub.result_dir) if sub.result_dir else None
        if sub.status != "graded" or folder is None or not (folder / FEEDBACK_NAME).is_file():
            raise HTTPException(404, "This attempt has no feedback yet; it is still being graded.")
        policy = self.course.assignment(sub.assignment)
        with self.factory() as session:
            people = rubrics.load(session, [sub])
            result = people.result(sub) if people.touches(sub.id) else read_result(folder)
            leveled = result is not None and any(t.level for t in result.tests)
            if result is None or policy is None or not (leveled or people.touches(sub.id)):
                return sandboxed((folder / FEEDBACK_NAME).read_text(encoding="utf-8"))
            # checks with a visibility level: rendered now, against the student's own
            # deadline, so passing it shows the "after_deadline" checks without a regrade
            deadline = deadline_for(session, policy, sub.user_id) if leveled else None
        if deadline is not None and deadline.tzinfo is None:
            deadline = deadline.replace(tzinfo=dt.timezone.utc)
        return sandboxed(render_feedback(folder, result, title=policy.title, deadline=deadline))


class NeedSignIn(Exception):
    pass


class TooManyWrongTokens(HTTPException):
    """The client's address tried too many wrong access tokens; it waits ``seconds``."""

    def __init__(self, seconds: int) -> None:
        self.seconds = seconds
        super().__init__(429, wait_message(seconds), headers={"Retry-After": str(seconds)})


def wait_message(seconds: int) -> str:
    return ("Too many wrong access tokens were tried from your network, so signing in from it "
            f"is paused. Try again in {math.ceil(seconds / 60)} minute(s), with the token your "
            "instructor sent you.")


def client_address(request: Request) -> str:
    """The throttled unit of the request's client (see :func:`throttle.client_key`)."""
    return throttle.client_key(request.client.host if request.client else None)


_UNKNOWN = object()


# -- dependencies: the course and the signed-in user ----------------------------------

async def the_service(request: Request) -> Service:
    """The course, database and store of this app (``app.state.service``)."""
    return request.app.state.service


ServiceState = Annotated[Service, Depends(the_service)]


def maybe_signed_in(request: Request, svc: ServiceState) -> Who | None:
    """The request's user, or ``None`` (a database read: FastAPI runs it in a thread)."""
    return svc.who(request)


MaybeSignedIn = Annotated[Who | None, Depends(maybe_signed_in)]


async def signed_in(who: MaybeSignedIn) -> Who:
    """The request's user; the sign-in answer (401 or the login page) when there is none."""
    if who is None:
        raise NeedSignIn()
    return who


SignedIn = Annotated[Who, Depends(signed_in)]


@dataclass(frozen=True)
class Mine:
    """The signed-in user and a submission of theirs (staff: anyone's)."""

    who: Who
    sub: Submission


def my_submission(sub_id: int, who: MaybeSignedIn, svc: ServiceState) -> Mine:
    """The submission of the path if the user may read it, else 404.

    The id is this dependency's own parameter and the user comes out of it too:
    FastAPI checks a dependency's parameters before calling it, but only after
    running the dependencies listed before it, so a separate ``SignedIn`` would
    ask a malformed id's request to sign in; this way it still answers 422.
    """
    if who is None:
        raise NeedSignIn()
    with svc.factory() as session:
        return Mine(who, svc.submission(session, who, sub_id))


MySubmission = Annotated[Mine, Depends(my_submission)]


def _staff(who: Who, *, instructor: bool) -> Who:
    if not who.staff or (instructor and who.role != "instructor"):
        raise HTTPException(403, "Only the course's instructors may open this page."
                            if instructor else "Only course staff may open this page.")
    return who


async def staff_member(who: SignedIn) -> Who:
    """A teaching assistant or an instructor, else 403."""
    return _staff(who, instructor=False)


async def instructor(who: SignedIn) -> Who:
    """An instructor, else 403."""
    return _staff(who, instructor=True)


async def assignment_policy(name: str, svc: ServiceState) -> AssignmentPolicy:
    """The assignment named in the path, else 404."""
    return svc.policy(name)


StaffMember = Annotated[Who, Depends(staff_member)]
Instructor = Annotated[Who, Depends(instructor)]
Assignment = Annotated[AssignmentPolicy, Depends(assignment_policy)]


# -- forms ----------------------------------------------------------------------------

def wants_json(request: Request, who: Who | None) -> bool:
    return (who is not None and who.via == "bearer") or \
        "application/json" in request.headers.get("accept", "")


async def upload_form(request: Request, svc: Service) -> Any:
    """The form of an upload; :class:`~autograder.service.bounds.BodyLimit` stops it at its limit."""
    try:
        return await request.form(max_files=1, max_fields=20, max_part_size=8 * 1024)
    except RequestTooLarge as exc:
        raise UploadRejected(f"The upload is larger than uploads may be: at most "
                             f"{svc.course.max_upload_bytes / 1e6:.1f} MB; nothing was stored. "
                             "Clear the notebook's outputs (Kernel > Restart & Clear Output) and "
                             "upload it again.", status=exc.status_code) from None


def check_csrf(who: Who, form: Any, request: Request) -> None:
    if who.via == "bearer":
        return  # no cookie involved: another site cannot make the browser send a token
    given = form.get("csrf") if form is not None else None
    given = given or request.headers.get("x-csrf-token")
    if not isinstance(given, str) or not auth.same_secret(given, who.csrf):
        raise HTTPException(403, "This form is out of date or was not sent by this site; "
                                 "reload the page and try again.")


def sandboxed(html: str) -> HTMLResponse:
    """A page holding student-written text: no script, opaque origin."""
    return HTMLResponse(html, headers={"Content-Security-Policy": SANDBOX_CSP,
                                       "X-Content-Type-Options": "nosniff"})


def safe_next(target: str) -> str:
    """Only a path on this site (never ``//evil`` or ``https://...``)."""
    parts = urlsplit(target)
    if parts.scheme or parts.netloc or not target.startswith("/") or target.startswith("//"):
        return "/"
    return target


# -- headers and error pages ---------------------------------------------------------

async def security_headers(request: Request, call_next: Callable[..., Any]) -> Response:
    response = await call_next(request)
    response.headers.setdefault("X-Content-Type-Options", "nosniff")
    response.headers.setdefault("Referrer-Policy", "same-origin")
    response.headers.setdefault("X-Frame-Options", "DENY")
    if request.url.path.startswith(("/submissions", "/instructor", "/api", "/assignments")):
        response.headers.setdefault("Cache-Control", "no-store")
    return response


def _json_error(request: Request) -> bool:
    return request.url.path.startswith("/api") or "application/json" in request.headers.get("accept", "")


async def need_sign_in(request: Request, exc: NeedSignIn) -> Response:
    if _json_error(request):
        return JSONResponse({"error": "Sign in first: send 'Authorization: Bearer TOKEN' "
                                      "with your access token."}, status_code=401)
    target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
    return RedirectResponse(f"/login?next={quote(target)}", status_code=303)


async def http_error(request: Request, exc: HTTPException) -> Response:
    headers = getattr(exc, "headers", None) or {}
    if _json_error(request):
        return JSONResponse({"error": exc.detail}, status_code=exc.status_code, headers=headers)
    svc: Service = request.app.state.service
    try:
        who = await run_in_threadpool(svc.who, request)
    except HTTPException:  # a throttled address: the page is shown signed out
        who = None
    response = svc.page("error.html.j2", who, status=exc.status_code, message=exc.detail)
    response.headers.update(headers)
    return response
