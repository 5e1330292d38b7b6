"""Where a student stands on an assignment: deadline, attempts, the attempt that counts, the score.

Only graded attempts count; an attempt whose grading failed (outcome "error")
never shows as a zero. With ``count = "last"`` the newest graded attempt
counts, with ``"best"`` the one with the highest score after its late penalty.
Scores include people's grading once released and instructors' overrides
(:mod:`~autograder.service.rubrics`), so the LMS gets the same score as every export.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from typing import Sequence

from sqlalchemy import select
from sqlalchemy.orm import Session

from autograder.service import rubrics
from autograder.service.course import AssignmentPolicy, Course
from autograder.service.models import Extension, Submission, User


def final_score(submission: Submission, raw: float | None = None) -> float | None:
    """The score after the late penalty (``None`` until graded); ``raw``: the combined score."""
    if submission.status != "graded" or submission.score is None:
        return None
    return round((submission.score if raw is None else raw) * (1.0 - submission.penalty), 6)


@dataclass(frozen=True)
class Standing:
    policy: AssignmentPolicy
    deadline: dt.datetime
    closes: dt.datetime
    attempts: tuple[Submission, ...]  # newest first
    counted: Submission | None
    #: people's grading of the attempts (manual points, overrides)
    people: rubrics.Adjustments = field(default_factory=rubrics.Adjustments)

    def final(self, sub: Submission) -> float | None:
        """An attempt's score after its late penalty, with people's grading in."""
        return final_score(sub, self.people.raw_score(sub))

    @property
    def raw_score(self) -> float | None:
        return None if self.counted is None else self.people.raw_score(self.counted)

    @property
    def pending(self) -> int:
        return sum(1 for s in self.attempts if s.status in ("queued", "running"))

    @property
    def score(self) -> float | None:
        return None if self.counted is None else self.final(self.counted)

    @property
    def max_score(self) -> float | None:
        return None if self.counted is None else self.counted.max_score

    def is_open(self, now: dt.datetime) -> bool:
        return self.policy.opens <= now < self.closes


def counted(policy: AssignmentPolicy, attempts: Sequence[Submission],
            people: rubrics.Adjustments | None = None) -> Submission | None:
    graded = [s for s in attempts if s.status == "graded" and s.score is not None]
    if not graded:
        return None
    if policy.count == "last":
        return max(graded, key=lambda s: (s.submitted_at, s.id))
    people = people or rubrics.Adjustments()
    return max(graded, key=lambda s: (final_score(s, people.raw_score(s)) or 0.0,
                                      s.submitted_at, s.id))


def _standing(policy: AssignmentPolicy, deadline: dt.datetime, attempts: tuple[Submission, ...],
              people: rubrics.Adjustments) -> Standing:
    return Standing(policy=policy, deadline=deadline, closes=policy.closes_for(deadline),
                    attempts=attempts, counted=counted(policy, attempts, people), people=people)


def deadline_for(session: Session, policy: AssignmentPolicy, user_id: str) -> dt.datetime:
    row = session.get(Extension, (user_id, policy.name))
    return policy.deadline_for(user_id, row.deadline if row is not None else None)


def standing(session: Session, policy: AssignmentPolicy, user_id: str) -> Standing:
    deadline = deadline_for(session, policy, user_id)
    attempts = tuple(session.scalars(
        select(Submission).where(Submission.user_id == user_id,
                                 Submission.assignment == policy.name)
        .order_by(Submission.submitted_at.desc(), Submission.id.desc())))
    return _standing(policy, deadline, attempts, rubrics.load(session, attempts))


def class_standings(session: Session, course: Course, policy: AssignmentPolicy
                    ) -> list[tuple[User, Standing]]:
    """Every student on the roster with their standing (students without attempts included)."""
    users = session.scalars(select(User).where(User.role == "student").order_by(User.id)).all()
    extensions = {e.user_id: e.deadline for e in session.scalars(
        select(Extension).where(Extension.assignment == policy.name))}
    by_user: dict[str, list[Submission]] = {}
    subs = session.scalars(select(Submission).where(Submission.assignment == policy.name)
                           .order_by(Submission.submitted_at.desc(), Submission.id.desc())).all()
    for sub in subs:
        by_user.setdefault(sub.user_id, []).append(sub)
    people = rubrics.load(session, subs)
    rows = []
    for user in users:
        deadline = policy.deadline_for(user.id, extensions.get(user.id))
        attempts = tuple(by_user.get(user.id, ()))
        rows.append((user, _standing(policy, deadline, attempts, people)))
    return rows


def time_left(until: dt.datetime, now: dt.datetime) -> str:
    """"2 days 3 h", "45 min", or "passed"."""
    seconds = (until - now).total_seconds()
    if seconds <= 0:
        return "passed"
    days, rest = divmod(int(seconds), 86400)
    hours, rest = divmod(rest, 3600)
    minutes = rest // 60
    if days:
        return f"{days} day{'s' if days > 1 else ''} {hours} h"
    if hours:
        return f"{hours} h {minutes} min"
    return f"{max(minutes, 1)} min"
