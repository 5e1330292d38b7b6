"""The web application: the routers of the student pages, the instructor pages and the JSON API.

Pages are Jinja2 templates (autoescaped) with one small script for the live
status and drag-and-drop; everything is served by the service (no CDN). Feedback
and summary pages contain text written by students, so they are served with
``Content-Security-Policy: sandbox`` and no script: they run in an opaque origin
and cannot read or act on the service. Every object is looked up through the
signed-in user, so changing an id in a URL finds nothing that is not theirs
(the answer is the same 404 as for an id that does not exist).

The routes live in :mod:`~autograder.service.pages_student`,
:mod:`~autograder.service.pages_staff`, :mod:`~autograder.service.api_routes` and
:mod:`~autograder.service.install` (the student's wheel);
what they share (the user and course dependencies, CSRF, error pages) in
:mod:`~autograder.service.web`. This module only assembles them.
"""

from __future__ import annotations

import secrets

from fastapi import FastAPI, HTTPException
from fastapi.staticfiles import StaticFiles
from sqlalchemy.orm import Session, sessionmaker

from autograder.service import (
    api_routes,
    install,
    pages_grading,
    pages_review,
    pages_staff,
    pages_student,
)
from autograder.service.bounds import BodyLimit
from autograder.service.course import Course
from autograder.service.lti import routes as lti
from autograder.service.storage import Storage
from autograder.service.waits import Waits
from autograder.service.web import HERE, NeedSignIn, Service, http_error, need_sign_in, security_headers


def create_app(course: Course, factory: sessionmaker[Session], *, secret: bytes | None = None,
               waits: Waits | None = None) -> FastAPI:
    """The ASGI application for ``course`` over the database behind ``factory``; ``waits``
    is woken by the service's grading processes (see :mod:`autograder.service.waits`)."""
    app = FastAPI(title=f"numgrade: {course.name}", docs_url=None, redoc_url=None, openapi_url=None)
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")
    app.state.service = Service(course, factory, Storage(course.data_dir),
                                secret or secrets.token_bytes(32), waits)
    # the innermost middleware, so the routes' parsers read the body through it directly and
    # its 413 reaches the routes' handlers as it is (not wrapped by another middleware's task group)
    app.add_middleware(BodyLimit, max_upload_bytes=course.max_upload_bytes)
    app.middleware("http")(security_headers)
    app.add_exception_handler(NeedSignIn, need_sign_in)
    app.add_exception_handler(HTTPException, http_error)
    for router in (pages_student.router, api_routes.router, pages_review.router,
                   pages_grading.router, pages_staff.router, lti.router,
                   install.router):
        app.include_router(router)
    return app
