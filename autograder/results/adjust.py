"""A result with people's grading folded in: manual points and instructors' overrides.

The grader leaves every manually graded cell as a check of kind
``needs-person`` with no points; once a person has graded it (and staff have
released it, for what students see) this module puts those points in, and then
applies the instructors' overrides of one check or of the total. The result that
comes out is what every export reads, so grades.csv, the Canvas CSV, JUnit, the
summary and the score that counts all add up the same way.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping

from autograder.results.model import CheckResult, SubmissionResult

#: the kind of a check a person has graded, and of the line an override of the total adds
PERSON, OVERRIDE = "graded-by-person", "override"
#: the name of the line that carries an override of the total
TOTAL_LINE = "Score set by the instructor"


@dataclass(frozen=True)
class ManualMark:
    """A person's grading of one answer: points (already clamped to the question's) and why."""

    points: float
    items: tuple[tuple[str, float], ...]
    comment: str

    def to_text(self) -> str:
        lines = [f"{text} ({points:+g})" for text, points in self.items]
        if self.comment:
            lines.append(self.comment)
        return "\n".join(lines) or "Graded by a person."


@dataclass(frozen=True)
class ScoreOverride:
    """An instructor's score for one check (``check == ""``: the total), with the reason."""

    check: str
    score: float
    reason: str


def clamp(points: float, max_score: float) -> float:
    return round(min(max(points, 0.0), max_score), 6)


def _marked(check: CheckResult, mark: ManualMark) -> CheckResult:
    score = clamp(mark.points, check.max_score)
    return replace(check, score=score, kind="ok" if score >= check.max_score else PERSON,
                   output=mark.to_text())


def _overridden(check: CheckResult, override: ScoreOverride) -> CheckResult:
    score = clamp(override.score, check.max_score)
    kind = "ok" if score >= check.max_score else "partial"
    return replace(check, score=score, kind=kind,
                   output=f"Score set by the instructor: {override.reason}\n\n{check.output}".strip())


def adjust(result: SubmissionResult, marks: Mapping[str, ManualMark],
           overrides: Mapping[str, ScoreOverride]) -> SubmissionResult:
    """``result`` with ``marks`` (by question) and ``overrides`` (by check, ``""`` the total)."""
    tests = []
    for check in result.tests:
        if check.kind == "needs-person" and check.name in marks:
            check = _marked(check, marks[check.name])
        if check.name in overrides:
            check = _overridden(check, overrides[check.name])
        tests.append(check)
    adjusted = result.with_tests(tuple(tests))
    total = overrides.get("")
    if total is None:
        return adjusted
    # written as one more line of the result, so the checks still add up to the score
    delta = round(max(total.score, 0.0) - adjusted.score, 6)
    line = CheckResult(name=TOTAL_LINE, score=delta, max_score=0.0, hidden=False, kind=OVERRIDE,
                       output=f"The total was set to {max(total.score, 0.0):g}: {total.reason}")
    return adjusted.with_tests((*tests, line))
