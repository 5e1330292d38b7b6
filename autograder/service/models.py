"""The service's tables (SQLAlchemy 2 declarative); the schema itself is made by Alembic.

Times are naive UTC everywhere (SQLite keeps no time zone).
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import DateTime, Float, ForeignKey, Integer, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column


def utcnow() -> dt.datetime:
    return dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)


class Base(DeclarativeBase):
    pass


class User(Base):
    """A roster entry: its id is the id in every export."""

    __tablename__ = "users"
    id: Mapped[str] = mapped_column(String(128), primary_key=True)
    name: Mapped[str] = mapped_column(String(256), default="")
    email: Mapped[str] = mapped_column(String(256), default="")
    role: Mapped[str] = mapped_column(String(16), default="student")  # student | ta | instructor
    #: Canvas's own user id (the roster's optional ``canvas_id`` column): the Canvas CSV's "ID"
    canvas_id: Mapped[str] = mapped_column(String(32), default="", server_default="")
    #: SHA-256 of the access token (tokens are 192 random bits, so a fast hash suffices)
    token_hash: Mapped[str | None] = mapped_column(String(64), unique=True, nullable=True)


class BrowserLogin(Base):
    """A signed-in browser: the cookie holds a random id, the table its hash and CSRF token."""

    __tablename__ = "web_sessions"
    id_hash: Mapped[str] = mapped_column(String(64), primary_key=True)
    user_id: Mapped[str] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    csrf: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)


class SignInFailure(Base):
    """Wrong access tokens from one client address in the current window (the sign-in throttle).

    Kept in the database, not in a process, so every service process counts the same failures.
    """

    __tablename__ = "sign_in_failures"
    client: Mapped[str] = mapped_column(String(64), primary_key=True)
    failures: Mapped[int] = mapped_column(Integer, default=0)
    window_start: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow, index=True)
    locked_until: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)


class Extension(Base):
    """A deadline set by the instructor for one student on one assignment."""

    __tablename__ = "extensions"
    user_id: Mapped[str] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), primary_key=True)
    assignment: Mapped[str] = mapped_column(String(128), primary_key=True)
    deadline: Mapped[dt.datetime] = mapped_column(DateTime)


class Submission(Base):
    """One accepted upload and its current result (kept until a regrade's result is in)."""

    __tablename__ = "submissions"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    user_id: Mapped[str] = mapped_column(ForeignKey("users.id"), index=True)
    assignment: Mapped[str] = mapped_column(String(128), index=True)
    sha256: Mapped[str] = mapped_column(String(64))
    filename: Mapped[str] = mapped_column(String(256))
    submitted_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow, index=True)
    late_days: Mapped[int] = mapped_column(Integer, default=0)
    penalty: Mapped[float] = mapped_column(Float, default=0.0)
    status: Mapped[str] = mapped_column(String(16), default="queued")  # queued|running|graded|error
    outcome: Mapped[str | None] = mapped_column(String(16), nullable=True)
    score: Mapped[float | None] = mapped_column(Float, nullable=True)
    max_score: Mapped[float | None] = mapped_column(Float, nullable=True)
    result_json: Mapped[str | None] = mapped_column(Text, nullable=True)
    result_dir: Mapped[str | None] = mapped_column(String(512), nullable=True)
    graded_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)


class Job(Base):
    """A queued grading of a submission; claimed with a lease, done exactly once."""

    __tablename__ = "jobs"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), index=True)
    kind: Mapped[str] = mapped_column(String(16), default="grade")  # grade | regrade
    priority: Mapped[int] = mapped_column(Integer, default=0)  # fresh uploads before regrades
    state: Mapped[str] = mapped_column(String(16), default="queued", index=True)  # queued|running|done|failed
    tries: Mapped[int] = mapped_column(Integer, default=0)
    claim: Mapped[str | None] = mapped_column(String(64), nullable=True)
    lease_until: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)
    finished_at: Mapped[dt.datetime | None] = mapped_column(DateTime, nullable=True)
    error: Mapped[str] = mapped_column(Text, default="")


class Grading(Base):
    """The ledger of committed gradings: one row per job, never two (exactly once)."""

    __tablename__ = "gradings"
    __table_args__ = (UniqueConstraint("job_id", name="uq_gradings_job"),)
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"))
    submission_id: Mapped[int] = mapped_column(ForeignKey("submissions.id"), index=True)
    worker: Mapped[str] = mapped_column(String(128))
    outcome: Mapped[str] = mapped_column(String(16))
    finished_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)
