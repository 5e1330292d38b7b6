"""The service's defaults and what a grader process is started with (stdlib only).

Kept apart from :mod:`autograder.service.pool` (which starts the processes) and
:mod:`autograder.service.jobqueue` (which leases jobs) so that both, and the
processes themselves, read one definition without importing each other. The
sign-in and request-size defaults live here too, beside the lease, so the course
file, the routes and the docs name one value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autograder.runners.jobs import DaskSpec

#: seconds a claim lasts without renewal (the default of ``--lease``)
LEASE_SECONDS = 30.0

#: hours a browser session lasts after sign-in (``[auth] session_hours`` in the course file)
SESSION_HOURS = 12.0
#: wrong access tokens from one client address within ``SIGN_IN_WINDOW_MINUTES`` before
#: that address must wait out the rest of the window (a class behind one NAT shares it, so
#: generous: a typo or two per student never locks a room out)
SIGN_IN_FAILURES = 20
SIGN_IN_WINDOW_MINUTES = 15
#: bytes of a request body that is not an upload (every form of the site is far smaller)
FORM_BYTES = 64 * 1024
#: bytes an upload's form may hold beyond ``max_upload_bytes`` (the CSRF field, part headers)
UPLOAD_FORM_SLACK = 16 * 1024


@dataclass(frozen=True)
class GraderSettings:
    """What a grading process needs (picklable: it crosses a ``spawn``)."""

    course_path: str
    database_url: str
    lease_seconds: float = LEASE_SECONDS
    poll_seconds: float = 0.2
    #: grade on this Dask cluster: the pool then runs one dispatcher instead of graders
    dask: "DaskSpec | None" = None
