"""The tables of manual grading: rubric items, graded answers, releases, overrides, regrade requests.

They share :class:`~autograder.service.models.Base` (one schema, made by the
migration ``0004_manual``). A *question* is a manually graded cell's name (the
nbgrader ``grade_id``, or the name under ``[[manual]]`` in assignment.toml); an
override or a regrade request names a *check* (a check's name, or ``""`` for the
submission's total).
"""

from __future__ import annotations

import datetime as dt

from sqlalchemy import DateTime, Float, ForeignKey, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from autograder.service.models import Base, utcnow


class RubricItem(Base):
    """A rubric item staff defined for one question; reused across every answer to it."""

    __tablename__ = "rubric_items"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    assignment: Mapped[str] = mapped_column(String(128), index=True)
    question: Mapped[str] = mapped_column(String(128))
    text: Mapped[str] = mapped_column(Text)
    points: Mapped[float] = mapped_column(Float)


class AnswerGrade(Base):
    """A person's grading of one answer: the free comment (the points come from applied items)."""

    __tablename__ = "answer_grades"
    submission_id: Mapped[int] = mapped_column(
        ForeignKey("submissions.id", ondelete="CASCADE"), primary_key=True)
    question: Mapped[str] = mapped_column(String(128), primary_key=True)
    comment: Mapped[str] = mapped_column(Text, default="")
    grader: Mapped[str] = mapped_column(String(128))
    updated_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)


class AppliedItem(Base):
    """A rubric item applied to one answer (its points are read from the item, so an edit follows)."""

    __tablename__ = "applied_items"
    submission_id: Mapped[int] = mapped_column(
        ForeignKey("submissions.id", ondelete="CASCADE"), primary_key=True)
    item_id: Mapped[int] = mapped_column(ForeignKey("rubric_items.id", ondelete="CASCADE"),
                                         primary_key=True)


class Release(Base):
    """Staff released the manual grading of a question (``question == ""``: the whole assignment)."""

    __tablename__ = "manual_releases"
    assignment: Mapped[str] = mapped_column(String(128), primary_key=True)
    question: Mapped[str] = mapped_column(String(128), primary_key=True)
    released_by: Mapped[str] = mapped_column(String(128))
    released_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)


class Override(Base):
    """A score set by an instructor, with the reason; rows are never changed (the history)."""

    __tablename__ = "score_overrides"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    submission_id: Mapped[int] = mapped_column(
        ForeignKey("submissions.id", ondelete="CASCADE"), index=True)
    check: Mapped[str] = mapped_column(String(256))  # "" = the total
    score: Mapped[float | None] = mapped_column(Float, nullable=True)  # None = override removed
    reason: Mapped[str] = mapped_column(Text)
    author: Mapped[str] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)


class RegradeRequest(Base):
    """A student's request to look again at one check or answer of a submission."""

    __tablename__ = "regrade_requests"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    submission_id: Mapped[int] = mapped_column(
        ForeignKey("submissions.id", ondelete="CASCADE"), index=True)
    check: Mapped[str] = mapped_column(String(256))
    status: Mapped[str] = mapped_column(String(16), default="open")  # open | answered
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)


class RegradeMessage(Base):
    """One message of a regrade request's thread (the student's or staff's)."""

    __tablename__ = "regrade_messages"
    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    request_id: Mapped[int] = mapped_column(
        ForeignKey("regrade_requests.id", ondelete="CASCADE"), index=True)
    author: Mapped[str] = mapped_column(String(128))
    staff: Mapped[bool] = mapped_column(default=False)
    text: Mapped[str] = mapped_column(Text)
    created_at: Mapped[dt.datetime] = mapped_column(DateTime, default=utcnow)
