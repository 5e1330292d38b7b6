"""Rubrics and people's grading in the database (no web): items, applying them, releases, overrides.

The points of an answer are never stored: they are the sum of the rubric items
applied to it, clamped to the question's points, read when needed, so editing
an item's points changes every answer it was applied to. What a student sees is
released per question (or for the whole assignment, ``question == ""``);
overrides are rows never changed, the newest per check counts (``score`` None:
taken away).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

from sqlalchemy import select
from sqlalchemy.orm import Session

from autograder.results.adjust import ManualMark, ScoreOverride, adjust, clamp
from autograder.results.model import SubmissionResult
from autograder.service.manual_models import AnswerGrade, AppliedItem, Override, Release, RubricItem
from autograder.service.models import Submission, utcnow


@dataclass(frozen=True)
class Adjustments:
    """People's grading of some submissions: marks by (submission, question), overrides."""

    marks: Mapping[tuple[int, str], ManualMark] = field(default_factory=dict)
    overrides: Mapping[int, Mapping[str, ScoreOverride]] = field(default_factory=dict)
    released: frozenset[tuple[str, str]] = frozenset()  # (assignment, question or "")

    def is_released(self, assignment: str, question: str) -> bool:
        return (assignment, "") in self.released or (assignment, question) in self.released

    def touches(self, sub_id: int) -> bool:
        return sub_id in self.overrides or any(s == sub_id for s, _ in self.marks)

    def result(self, sub: Submission, *, released_only: bool = True) -> SubmissionResult | None:
        """The submission's result with people's grading in (``None`` until graded)."""
        if sub.result_json is None:
            return None
        result = SubmissionResult.from_dict(json.loads(sub.result_json))
        marks = {q: m for (s, q), m in self.marks.items() if s == sub.id
                 and (not released_only or self.is_released(sub.assignment, q))}
        return adjust(result, marks, self.overrides.get(sub.id, {}))

    def raw_score(self, sub: Submission) -> float | None:
        """The combined score before the late penalty (the automatic one when nobody graded)."""
        if sub.status != "graded" or sub.score is None:
            return None
        if not self.touches(sub.id):
            return sub.score
        result = self.result(sub)
        return None if result is None else result.score


def load(session: Session, subs: Sequence[Submission]) -> Adjustments:
    """The marks, overrides and releases that concern ``subs``."""
    ids = [s.id for s in subs]
    if not ids:
        return Adjustments()
    marks = marks_for(session, ids)
    overrides: dict[int, dict[str, ScoreOverride]] = {}
    for row in session.scalars(select(Override).where(Override.submission_id.in_(ids))
                               .order_by(Override.id)):
        mine = overrides.setdefault(row.submission_id, {})
        if row.score is None:
            mine.pop(row.check, None)
        else:
            mine[row.check] = ScoreOverride(row.check, row.score, row.reason)
    names = {s.assignment for s in subs}
    released = frozenset(tuple(row) for row in session.execute(
        select(Release.assignment, Release.question).where(Release.assignment.in_(names))))
    return Adjustments(marks, {k: v for k, v in overrides.items() if v}, released)


def marks_for(session: Session, ids: Iterable[int]) -> dict[tuple[int, str], ManualMark]:
    """Every graded answer of the submissions ``ids``: its applied items and comment."""
    ids = list(ids)
    items: dict[tuple[int, str], list[tuple[str, float]]] = {}
    for sub_id, item in session.execute(
            select(AppliedItem.submission_id, RubricItem)
            .join(RubricItem, AppliedItem.item_id == RubricItem.id)
            .where(AppliedItem.submission_id.in_(ids)).order_by(RubricItem.id)):
        items.setdefault((sub_id, item.question), []).append((item.text, item.points))
    marks = {}
    for grade in session.scalars(select(AnswerGrade).where(AnswerGrade.submission_id.in_(ids))):
        key = (grade.submission_id, grade.question)
        applied = tuple(items.get(key, ()))
        marks[key] = ManualMark(sum(p for _, p in applied), applied, grade.comment)
    return marks


# -- changing ----------------------------------------------------------------------------

def clamp_points(mark: ManualMark, max_score: float) -> float:
    """The points an answer gets: its items' sum, between 0 and the question's points."""
    return clamp(mark.points, max_score)


def items(session: Session, assignment: str, question: str) -> list[RubricItem]:
    return list(session.scalars(select(RubricItem).where(
        RubricItem.assignment == assignment, RubricItem.question == question).order_by(RubricItem.id)))


def grade_row(session: Session, sub_id: int, question: str, grader: str) -> AnswerGrade:
    """The answer's grading, made when a person first acts on it (so it counts as graded)."""
    row = session.get(AnswerGrade, (sub_id, question))
    if row is None:
        row = AnswerGrade(submission_id=sub_id, question=question, comment="", grader=grader,
                          updated_at=utcnow())
        session.add(row)
    row.grader, row.updated_at = grader, utcnow()
    return row


def toggle_item(session: Session, sub: Submission, item: RubricItem, grader: str) -> bool:
    """Apply ``item`` to the answer, or take it off when it was applied; whether it is on now."""
    grade_row(session, sub.id, item.question, grader)
    row = session.get(AppliedItem, (sub.id, item.id))
    if row is not None:
        session.delete(row)
        return False
    session.add(AppliedItem(submission_id=sub.id, item_id=item.id))
    return True


def applied_ids(session: Session, sub_id: int) -> set[int]:
    return set(session.scalars(select(AppliedItem.item_id).where(AppliedItem.submission_id == sub_id)))


def release(session: Session, assignment: str, question: str, who: str) -> None:
    if session.get(Release, (assignment, question)) is None:
        session.add(Release(assignment=assignment, question=question, released_by=who,
                            released_at=utcnow()))


def add_override(session: Session, sub: Submission, check: str, score: float | None,
                 reason: str, who: str) -> Override:
    row = Override(submission_id=sub.id, check=check, score=score, reason=reason, author=who,
                   created_at=utcnow())
    session.add(row)
    return row


def history(session: Session, sub_id: int) -> list[Override]:
    return list(session.scalars(select(Override).where(Override.submission_id == sub_id)
                                .order_by(Override.id)))
