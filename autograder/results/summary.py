"""The class summary: ``DIR/summary.json`` and ``DIR/summary.html`` from all results of a batch.

What an instructor reads after a batch: the score distribution, the pass rate
of every check (hardest first), the mean grading time, and the submissions
that need a person.

Suspected hard-coding
---------------------
A submission that passes every public check but fails every *unseen* check
probably prints the answers the public checks expect rather than computing
them. The *unseen* checks of a submission are its hidden checks whose dataset
id starts with ``"unseen"`` (the assignments name datasets that students never
saw ``unseen-*``, e.g. ``convex_hull[unseen-circle]``); when a submission has
no such check, all its hidden checks count as unseen. A check fails when it
did not get full marks (partial credit is a failure here). A submission is
flagged when it has at least one public and at least one unseen check, passed
all the public ones and failed all the unseen ones. A flag asks a person to
read the notebook; it changes no score.
"""

from __future__ import annotations

import json
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autograder.results.feedback import FEEDBACK_NAME, template_environment
from autograder.results.files import atomic_write_text
from autograder.results.model import SUBMISSION_NOTE, CheckResult, SubmissionResult

SUMMARY_JSON = "summary.json"
SUMMARY_HTML = "summary.html"
UNSEEN_PREFIX = "unseen"
HISTOGRAM_BINS = 10
HARD_CODING_RULE = (
    "passes every public check and fails (less than full marks) every unseen check; unseen "
    f"checks are hidden checks whose dataset id starts with {UNSEEN_PREFIX!r}, or all hidden "
    "checks when a submission has none of those")

#: why a submission needs a person, most urgent first
CONCERNS = {
    "error": "the grader failed",
    "ungradable": "file could not be graded",
    "submission": "the submission needs a look",
    "timeout": "a cell ran out of time",
    "crashed": "the worker stopped",
    "check-error": "a check itself failed",
    "forbidden": "uses a banned call",
    "hard-coding": "suspected hard-coding",
    "unverified": "code the scan could not verify",
}
#: how a result note addressed to the instructor starts (see autograder.engine.grader)
_REVIEW_PREFIX = "For the instructor: "


@dataclass(frozen=True)
class Bin:
    """One bar of the score histogram: submissions scoring ``low <= percent < high``."""

    low: float
    high: float
    count: int

    def to_dict(self) -> dict[str, Any]:
        return {"low": self.low, "high": self.high, "count": self.count}


@dataclass(frozen=True)
class CheckStats:
    """How the class did on one check."""

    name: str
    hidden: bool
    submissions: int
    passed: int
    mean_fraction: float  # mean of score / max_score

    @property
    def pass_rate(self) -> float:
        return self.passed / self.submissions if self.submissions else 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "hidden": self.hidden, "submissions": self.submissions,
                "passed": self.passed, "pass_rate": round(self.pass_rate, 6),
                "mean_fraction": round(self.mean_fraction, 6)}


@dataclass(frozen=True)
class Concern:
    """One reason a submission needs a person (``kind`` is a key of :data:`CONCERNS`)."""

    kind: str
    detail: str

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "detail": self.detail}


@dataclass(frozen=True)
class Attention:
    """A submission that needs a person, with every reason found."""

    id: str
    source: str
    score: float
    max_score: float
    concerns: tuple[Concern, ...]

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "source": self.source, "score": self.score,
                "max_score": self.max_score, "concerns": [c.to_dict() for c in self.concerns]}


@dataclass(frozen=True)
class Elsewhere:
    """A result kept on disk but not in the exports: its file is no longer given, or another
    file claims its id (``claimed_by``: that file; "" when none)."""

    id: str
    source: str
    claimed_by: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "source": self.source, "claimed_by": self.claimed_by}


@dataclass(frozen=True)
class StudentRow:
    """One submission's line in the per-student table: its id links to its feedback page."""

    id: str
    outcome: str
    score: float
    max_score: float
    passed: int
    checks: int

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "outcome": self.outcome, "score": self.score,
                "max_score": self.max_score, "passed": self.passed, "checks": self.checks}


def student_rows(results: Sequence[SubmissionResult]) -> tuple[StudentRow, ...]:
    """A row per submission, in id order."""
    return tuple(StudentRow(r.id, r.outcome, r.score, r.max_score,
                            sum(1 for t in r.tests if t.max_score and t.score >= t.max_score),
                            len(r.tests)) for r in sorted(results, key=lambda r: r.id))


@dataclass(frozen=True)
class ClassSummary:
    """Everything ``summary.json`` and ``summary.html`` say about a batch.

    Score statistics are over *scored* submissions: every outcome except
    ``"error"`` (the grader's own failure, regraded on the next run).
    Percentages are ``100 * score / max_score``.
    """

    assignment: str
    submissions: int
    scored: int
    outcomes: tuple[tuple[str, int], ...]
    percents: tuple[float, ...]
    histogram: tuple[Bin, ...]
    checks: tuple[CheckStats, ...]
    mean_seconds: float | None
    total_seconds: float
    attention: tuple[Attention, ...]
    #: results whose file was not given this time (kept on disk, not exported)
    no_longer_submitted: tuple[Elsewhere, ...] = ()
    #: results another file of this run claims the id of (neither is exported)
    conflicts: tuple[Elsewhere, ...] = ()
    #: one row per submission, for the per-student table
    students: tuple[StudentRow, ...] = ()

    @property
    def mean_percent(self) -> float | None:
        return statistics.fmean(self.percents) if self.percents else None

    @property
    def median_percent(self) -> float | None:
        return statistics.median(self.percents) if self.percents else None

    def to_dict(self) -> dict[str, Any]:
        def rounded(value: float | None) -> float | None:
            return None if value is None else round(value, 3)
        return {
            "assignment": self.assignment, "submissions": self.submissions,
            "scored": self.scored, "outcomes": dict(self.outcomes),
            "mean_percent": rounded(self.mean_percent),
            "median_percent": rounded(self.median_percent),
            "min_percent": rounded(min(self.percents, default=None)),
            "max_percent": rounded(max(self.percents, default=None)),
            "histogram": [b.to_dict() for b in self.histogram],
            "checks": [c.to_dict() for c in self.checks],
            "mean_seconds": rounded(self.mean_seconds), "total_seconds": rounded(self.total_seconds),
            "attention": [a.to_dict() for a in self.attention],
            "conflicts": [c.to_dict() for c in self.conflicts],
            "no_longer_submitted": [g.to_dict() for g in self.no_longer_submitted],
            "students": [row.to_dict() for row in self.students],
            "hard_coding_rule": HARD_CODING_RULE,
        }


def percent(result: SubmissionResult) -> float:
    """``100 * score / max_score`` (0 when nothing could be scored)."""
    return round(100.0 * result.score / result.max_score, 6) if result.max_score else 0.0


def histogram(percents: Sequence[float], bins: int = HISTOGRAM_BINS) -> tuple[Bin, ...]:
    """Equal bins over 0..100 %; a full score falls in the last bin."""
    width = 100.0 / bins
    counts = [0] * bins
    for value in percents:
        counts[min(max(int(value // width), 0), bins - 1)] += 1
    return tuple(Bin(round(k * width, 6), round((k + 1) * width, 6), n) for k, n in enumerate(counts))


def check_stats(results: Sequence[SubmissionResult]) -> tuple[CheckStats, ...]:
    """Pass rate of every check, the hardest (lowest pass rate, then lowest mean score) first."""
    seen: dict[str, list[CheckResult]] = {}
    for result in results:
        for check in result.tests:
            seen.setdefault(check.name, []).append(check)
    stats = [CheckStats(name=name, hidden=any(c.hidden for c in checks), submissions=len(checks),
                        passed=sum(c.status == "passed" for c in checks),
                        mean_fraction=statistics.fmean(
                            c.score / c.max_score if c.max_score else 0.0 for c in checks))
             for name, checks in seen.items()]
    return tuple(sorted(stats, key=lambda s: (s.pass_rate, s.mean_fraction, s.name)))


def unseen_checks(result: SubmissionResult) -> tuple[CheckResult, ...]:
    """The hidden checks on ``unseen*`` datasets, else all hidden checks (see the module notes)."""
    hidden = tuple(c for c in result.tests if c.hidden)
    unseen = tuple(c for c in hidden if (c.dataset or "").startswith(UNSEEN_PREFIX))
    return unseen or hidden


def suspected_hard_coding(result: SubmissionResult) -> bool:
    """Passes every public check and fails every unseen one (see the module notes)."""
    public = [c for c in result.tests if not c.hidden]
    unseen = unseen_checks(result)
    return (bool(public) and bool(unseen) and all(c.status == "passed" for c in public)
            and all(c.status == "failed" for c in unseen))


def concerns(result: SubmissionResult) -> tuple[Concern, ...]:
    """Every reason ``result`` needs a person, most urgent first (empty when none)."""
    found: list[Concern] = []
    if result.outcome != "graded":
        found.append(Concern(result.outcome, _short(result.output)))
    for kind in ("check-error", "forbidden"):
        names = [c.name for c in result.tests if c.kind == kind]
        if names:
            first = next(c.output for c in result.tests if c.kind == kind)
            found.append(Concern(kind, f"{_names(names)}: {_short(first)}"))
    about = [n[len(SUBMISSION_NOTE):] for n in result.notes if n.startswith(SUBMISSION_NOTE)]
    if about:
        found.append(Concern("submission", _short(" ".join(about))))
    review = [n[len(_REVIEW_PREFIX):] for n in result.notes if n.startswith(_REVIEW_PREFIX)]
    if review:
        found.append(Concern("unverified", _short(" ".join(review))))
    if suspected_hard_coding(result):
        unseen = unseen_checks(result)
        found.append(Concern("hard-coding",
                             f"passes all {sum(not c.hidden for c in result.tests)} public checks "
                             f"but fails all {len(unseen)} unseen ones ({_names([c.name for c in unseen])})"))
    order = list(CONCERNS)
    return tuple(sorted(found, key=lambda c: order.index(c.kind) if c.kind in order else len(order)))


def _short(text: str, limit: int = 300) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit - 1] + "…"


def _names(names: Sequence[str], limit: int = 4) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def needs_attention(results: Sequence[SubmissionResult]) -> tuple[Attention, ...]:
    """The submissions with at least one concern, the most urgent first, then by id."""
    flagged = [Attention(r.id, r.source, r.score, r.max_score, found)
               for r in results if (found := concerns(r))]
    order = list(CONCERNS)
    return tuple(sorted(flagged, key=lambda a: (min(order.index(c.kind) if c.kind in order
                                                    else len(order) for c in a.concerns), a.id)))


def summarise(results: Sequence[SubmissionResult], *, assignment: str = "",
              elsewhere: Sequence[Elsewhere] = ()) -> ClassSummary:
    """The class summary of ``results`` (one per submission, reused ones included).

    ``elsewhere``: results of the folder left out of ``results`` (no longer submitted,
    or in conflict with a file of this run).
    """
    scored = [r for r in results if r.outcome != "error"]
    outcomes: dict[str, int] = {}
    for result in results:
        outcomes[result.outcome] = outcomes.get(result.outcome, 0) + 1
    percents = tuple(percent(r) for r in scored)
    seconds = [r.execution_time for r in scored]
    return ClassSummary(
        assignment=assignment or next((r.assignment for r in results if r.assignment), ""),
        submissions=len(results), scored=len(scored), outcomes=tuple(sorted(outcomes.items())),
        percents=percents, histogram=histogram(percents), checks=check_stats(scored),
        mean_seconds=statistics.fmean(seconds) if seconds else None,
        total_seconds=sum(seconds), attention=needs_attention(results),
        no_longer_submitted=tuple(e for e in elsewhere if not e.claimed_by),
        conflicts=tuple(e for e in elsewhere if e.claimed_by), students=student_rows(results))


# -- the page -------------------------------------------------------------------

def histogram_bars(bins: Sequence[Bin], *, width: int = 640, height: int = 220,
                   margin: int = 28) -> list[dict[str, Any]]:
    """SVG geometry of the histogram: one rectangle per bin, in user units of a viewBox."""
    tallest = max((b.count for b in bins), default=0) or 1
    step = (width - 2 * margin) / max(len(bins), 1)
    plot = height - 2 * margin
    bars = []
    for k, b in enumerate(bins):
        h = plot * b.count / tallest
        bars.append({"x": round(margin + k * step + 2, 2), "w": round(step - 4, 2),
                     "y": round(margin + plot - h, 2), "h": round(h, 2), "count": b.count,
                     "label": f"{b.low:g}–{b.high:g}%", "mid": round(margin + (k + 0.5) * step, 2),
                     "low": f"{b.low:g}", "left": round(margin + k * step, 2)})
    return bars


def render_summary(summary: ClassSummary, *, title: str | None = None) -> str:
    """The HTML of the class summary page (links to each ``<id>/feedback.html``)."""
    template = template_environment().get_template("summary.html.j2")
    return template.render(
        title=title or summary.assignment, s=summary, concerns=CONCERNS,
        bars=histogram_bars(summary.histogram), svg={"width": 640, "height": 220, "margin": 28},
        feedback_name=FEEDBACK_NAME, rule=HARD_CODING_RULE,
        fmt=lambda v, digits=1: "–" if v is None else f"{v:.{digits}f}")


def write_summary(out_dir: Path, results: Sequence[SubmissionResult], *,
                  title: str | None = None, assignment: str = "",
                  elsewhere: Sequence[Elsewhere] = ()) -> ClassSummary:
    """Write ``summary.json`` and ``summary.html`` into ``out_dir`` atomically.

    Parameters
    ----------
    out_dir : Path
        The batch's results folder (holding ``<id>/results.json``).
    results : sequence of SubmissionResult
        One per submission, reused results included.
    title : str, optional
        The assignment's title for the page heading.
    assignment : str, optional
        The assignment's name (default: the one recorded in the results).
    elsewhere : sequence of Elsewhere, optional
        Results of the folder not in ``results``, listed apart.

    Returns
    -------
    ClassSummary
        What was written.
    """
    summary = summarise(results, assignment=assignment, elsewhere=elsewhere)
    atomic_write_text(out_dir / SUMMARY_JSON,
                      json.dumps(summary.to_dict(), indent=2, ensure_ascii=False))
    atomic_write_text(out_dir / SUMMARY_HTML, render_summary(summary, title=title))
    return summary


__all__ = [
    "CONCERNS",
    "HARD_CODING_RULE",
    "SUMMARY_HTML",
    "SUMMARY_JSON",
    "UNSEEN_PREFIX",
    "Attention",
    "Bin",
    "CheckStats",
    "ClassSummary",
    "Concern",
    "Elsewhere",
    "check_stats",
    "concerns",
    "histogram",
    "histogram_bars",
    "needs_attention",
    "percent",
    "render_summary",
    "summarise",
    "suspected_hard_coding",
    "unseen_checks",
    "write_summary",
]
