"""Starting the service: migrate the database, import the roster once, start graders and uvicorn."""

from __future__ import annotations

import dataclasses
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy import func, select

from autograder.engine.assignment import load_assignment
from autograder.errors import UsageError
from autograder.results.files import atomic_write_bytes
from autograder.runners.backends import load_dask_backend
from autograder.runners.jobs import DaskSpec
from autograder.service import auth, jobqueue
from autograder.service.course import Course, load_course
from autograder.service.db import make_engine, sessions, upgrade
from autograder.service.lti.outbox import ScoreSender
from autograder.service.models import User
from autograder.service.pool import GradingPool
from autograder.service.settings import GraderSettings
from autograder.service.waits import Waits


def open_course(course_path: str | Path, *, database: str | None = None) -> Course:
    """Load the course file (with ``database`` overriding its URL) and check every assignment loads."""
    course = load_course(course_path)
    if database:
        course = dataclasses.replace(course, database_url=database)
    for policy in course.assignments:
        load_assignment(policy.spec)  # fails now, with the loader's message, not at the first upload
    # uploads, results, the SQLite file and tokens.csv: for the service's user only (the
    # sandboxed worker runs as another user and must never read them)
    course.data_dir.mkdir(parents=True, exist_ok=True)
    course.data_dir.chmod(0o700)
    return course


@dataclass(frozen=True)
class RosterImport:
    """What ``autograder roster`` did: who was added, who was already there, where the tokens are."""

    added: tuple[str, ...]
    already: tuple[str, ...]
    tokens: Path | None  # the tokens file, when anyone got a new token
    new_tokens: int
    kept_tokens: int  # rows of the earlier tokens file kept beside the new ones
    #: identifiers of a GitHub Classroom roster's rows with no account linked (not imported)
    unlinked: tuple[str, ...] = ()


def import_roster(course: Course, roster: Path, *, tokens_out: Path | None = None) -> RosterImport:
    """Import ``roster`` into the course database; add new people's tokens to a CSV (mode 0600).

    The tokens file keeps every row it had whose token still opens the service,
    so importing a second roster never drops the tokens of the first.
    """
    engine = make_engine(course.database_url)
    try:
        upgrade(engine)
        entries = auth.read_roster(roster)
        unlinked = auth.unlinked_rows(roster)
        out = tokens_out or course.data_dir / "tokens.csv"
        with sessions(engine).begin() as session:
            changes = auth.import_roster(session, entries)
            if not changes.issued:
                return RosterImport(changes.added, changes.already, None, 0, 0, unlinked)
            kept = auth.kept_tokens(session, _read_text(out), besides=(u.id for u, _ in changes.issued))
            atomic_write_bytes(out, auth.tokens_csv([*kept, *changes.issued]).encode(), mode=0o600)
        return RosterImport(changes.added, changes.already, out, len(changes.issued), len(kept),
                            unlinked)
    finally:
        engine.dispose()


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return ""
    except OSError as exc:
        raise UsageError(f"Cannot read the tokens file {str(path)!r} to add to it: {exc.strerror}; "
                         "nothing was changed.") from None


def _secret(course: Course) -> bytes:
    """A per-course secret kept beside the data (for CSRF tokens of proxy-signed-in users)."""
    path = course.data_dir / "secret.key"
    if not path.exists():
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as handle:
            handle.write(secrets.token_bytes(32))
    return path.read_bytes()


def serve(course_path: str | Path, *, host: str = "127.0.0.1", port: int = 8000,
          database: str | None = None, jobs: int | None = None,
          lease_seconds: float | None = None, dask: DaskSpec | str | None = None,
          say: bool = True) -> None:
    """Run the service until interrupted (see ``autograder serve --help``).

    ``dask`` (a :class:`~autograder.runners.backends.DaskSpec`, or an address such as
    ``"local:2"``) grades on a Dask cluster through one dispatcher process
    instead of ``jobs`` local grading processes; it needs the ``dask`` extra.
    """
    import uvicorn

    from autograder.service.app import create_app

    spec = DaskSpec(dask) if isinstance(dask, str) else dask
    if spec is not None:
        if jobs is not None:
            raise UsageError("--jobs sets the number of local grading processes; with --dask the "
                             "cluster's grading slots set how many gradings run at once: give one "
                             "of the two.")
        load_dask_backend()  # a clear error now, naming the extra, when `distributed` is missing
    course = open_course(course_path, database=database)
    engine = make_engine(course.database_url)
    upgrade(engine)
    factory = sessions(engine)
    with factory() as session:
        empty = session.scalar(select(func.count()).select_from(User)) == 0
    if empty and course.roster is not None:
        done = import_roster(course, course.roster)
        if say:
            print(f"Imported {len(done.added)} people from {course.roster}; their access tokens "
                  f"are in {done.tokens} (only there: the database keeps hashes).", flush=True)
    settings = GraderSettings(course_path=str(course.path), database_url=course.database_url,
                              dask=spec, **({"lease_seconds": lease_seconds} if lease_seconds else {}))
    pool = GradingPool(settings, 1 if spec is not None else jobs or max(1, (os.cpu_count() or 2)))
    pool.start()
    jobqueue.wake_on_enqueue(pool.wake)  # uploads and regrades wake idle graders at once
    waits = Waits()
    waits.relay(pool.graded)  # and a grade recorded answers the requests waiting for it
    scores = ScoreSender(course, factory)  # LTI: scores to the LMS, pending ones first
    scores.start()
    if say:
        graders = (f"{pool.jobs} grading process(es)" if spec is None
                   else f"grading on the Dask cluster {spec.address}")
        print(f"Serving {course.name} on http://{host}:{port}/ with {graders}; "
              f"database {engine.url.render_as_string(hide_password=True)}.", flush=True)
    try:
        uvicorn.run(create_app(course, factory, secret=_secret(course), waits=waits), host=host,
                    port=port, log_level="warning", access_log=False)
    finally:
        scores.stop()
        jobqueue.wake_on_enqueue(None)
        pool.stop()
        engine.dispose()
