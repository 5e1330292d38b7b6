"""What a service grader process is started with, and how long a claim on a job lasts (stdlib only).

Kept apart from :mod:`autograder.service.pool` (which starts the processes) and
:mod:`autograder.service.jobqueue` (which leases jobs) so that both, and the
processes themselves, read one definition without importing each other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from autograder.runners.jobs import DaskSpec

#: seconds a claim lasts without renewal (the default of ``--lease``)
LEASE_SECONDS = 30.0


@dataclass(frozen=True)
class GraderSettings:
    """What a grading process needs (picklable: it crosses a ``spawn``)."""

    course_path: str
    database_url: str
    lease_seconds: float = LEASE_SECONDS
    poll_seconds: float = 0.2
    #: grade on this Dask cluster: the pool then runs one dispatcher instead of graders
    dask: "DaskSpec | None" = None
