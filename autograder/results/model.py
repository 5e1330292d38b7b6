"""Results as frozen dataclasses, each with ``to_dict()``.

The dictionary form of :class:`SubmissionResult` is the Gradescope
``results.json`` format (top-level ``score``, ``max_score``, ``execution_time``,
``output``, ``tests``), with this grader's own facts under ``extra_data``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal

Status = Literal["passed", "failed"]
Visibility = Literal["visible", "hidden", "after_due_date", "after_published"]
#: how grading of a whole submission ended
Outcome = Literal["graded", "ungradable", "timeout", "crashed", "error"]
#: how a note about the submission itself starts (a stray copy, an untouched template, deleted
#: cells): the summary lists every result with one under "needs a person"
SUBMISSION_NOTE = "About this submission: "


@dataclass(frozen=True)
class Attachment:
    """A picture attached to a check (e.g. the student's car beside the reference's)."""

    label: str
    filename: str  # relative to the submission's result folder

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "filename": self.filename}


@dataclass(frozen=True)
class CheckResult:
    """The verdict of one check item on one submission."""

    name: str
    score: float
    max_score: float
    output: str
    hidden: bool
    kind: str = "ok"  # ok | wrong | partial | exception | missing | timeout | not-run | unsupported | crashed | forbidden | check-error
    dataset: str | None = None
    attachments: tuple[Attachment, ...] = ()
    #: the assignment notebook the check belongs to, when an assignment has several
    notebook: str | None = None
    #: what a student sees (``visibility`` marker): hidden | after_deadline | input |
    #: visible; None: public checks in full, hidden ones by name, status and message
    level: str | None = None
    #: the check's description of its input (shown at the "input" level)
    shown_input: str = ""
    #: the student's outputs for varied quantities, recorded by ``variant.record``
    observed: tuple[tuple[str, Any], ...] = ()

    @property
    def status(self) -> Status:
        return "passed" if self.score >= self.max_score and self.kind == "ok" else "failed"

    @property
    def visibility(self) -> Visibility:
        """Gradescope's visibility: a check shown after the deadline is ``after_due_date``;
        the "hidden" and "input" levels are ``visible`` with their output cut by
        :func:`autograder.results.feedback.as_students_see`."""
        if self.level == "after_deadline":
            return "after_due_date"
        if self.level is not None:
            return "visible"
        return "after_published" if self.hidden else "visible"

    def to_dict(self) -> dict[str, Any]:
        entry: dict[str, Any] = {
            "name": self.name,
            "score": round(self.score, 6),
            "max_score": self.max_score,
            "status": self.status,
            "output": self.output,
            "visibility": self.visibility,
            "extra_data": {"kind": self.kind, "hidden": self.hidden, "dataset": self.dataset,
                           "attachments": [a.to_dict() for a in self.attachments]},
        }
        if self.notebook is not None:
            entry["extra_data"]["notebook"] = self.notebook
        if self.level is not None:
            entry["extra_data"]["level"] = self.level
        if self.shown_input:
            entry["extra_data"]["shown_input"] = self.shown_input
        if self.observed:
            entry["extra_data"]["observed"] = dict(self.observed)
        return entry

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "CheckResult":
        extra = data.get("extra_data", {})
        return cls(name=data["name"], score=float(data["score"]),
                   max_score=float(data["max_score"]), output=data.get("output", ""),
                   hidden=bool(extra.get("hidden", False)), kind=extra.get("kind", "ok"),
                   dataset=extra.get("dataset"), notebook=extra.get("notebook"),
                   level=extra.get("level"), shown_input=extra.get("shown_input", ""),
                   observed=tuple(dict(extra.get("observed", {})).items()),
                   attachments=tuple(Attachment(**a) for a in extra.get("attachments", [])))


@dataclass(frozen=True)
class CellError:
    """A code cell that raised while the notebook ran."""

    cell: int
    ename: str
    evalue: str
    traceback: str
    #: the assignment notebook, when an assignment has several
    notebook: str = ""

    def to_dict(self) -> dict[str, Any]:
        entry = {"cell": self.cell, "ename": self.ename, "evalue": self.evalue,
                 "traceback": self.traceback}
        if self.notebook:
            entry["notebook"] = self.notebook
        return entry


@dataclass(frozen=True)
class SubmissionResult:
    """Everything the grader concluded about one submitted file."""

    id: str
    source: str
    assignment: str
    key: str
    sha256: str
    outcome: Outcome
    output: str
    tests: tuple[CheckResult, ...]
    execution_time: float
    seed: int
    cell_errors: tuple[CellError, ...] = ()
    stdout: str = ""
    notes: tuple[str, ...] = ()
    engine: str = ""
    #: CPU seconds the student's code used (notebook and calls)
    cpu_seconds: float = 0.0
    max_score_declared: float | None = field(default=None, compare=False)
    #: the student's variant (student, seed, params) when the assignment has variants
    variant: dict[str, Any] | None = field(default=None, compare=False)

    @property
    def score(self) -> float:
        return round(sum(t.score for t in self.tests), 6)

    @property
    def max_score(self) -> float:
        if self.max_score_declared is not None:
            return self.max_score_declared
        return round(sum(t.max_score for t in self.tests), 6)

    def with_tests(self, tests: tuple[CheckResult, ...]) -> "SubmissionResult":
        return replace(self, tests=tests)

    def to_dict(self) -> dict[str, Any]:
        return {
            "score": self.score,
            "max_score": self.max_score,
            "execution_time": round(self.execution_time, 3),
            "output": self.output,
            "visibility": "visible",
            "stdout_visibility": "hidden",
            "tests": [t.to_dict() for t in self.tests],
            "extra_data": {
                "id": self.id, "source": self.source, "assignment": self.assignment,
                "key": self.key, "sha256": self.sha256, "outcome": self.outcome,
                "seed": self.seed, "engine": self.engine, "notes": list(self.notes),
                "cpu_seconds": self.cpu_seconds,
                "cell_errors": [c.to_dict() for c in self.cell_errors],
                "stdout": self.stdout,
                **({"variant": self.variant} if self.variant is not None else {}),
            },
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "SubmissionResult":
        extra = data.get("extra_data", {})
        return cls(
            id=extra["id"], source=extra.get("source", ""), assignment=extra.get("assignment", ""),
            key=extra.get("key", ""), sha256=extra.get("sha256", ""),
            outcome=extra.get("outcome", "graded"), output=data.get("output", ""),
            tests=tuple(CheckResult.from_dict(t) for t in data.get("tests", [])),
            execution_time=float(data.get("execution_time", 0.0)), seed=int(extra.get("seed", 0)),
            cell_errors=tuple(CellError(**c) for c in extra.get("cell_errors", [])),
            stdout=extra.get("stdout", ""), notes=tuple(extra.get("notes", [])),
            engine=extra.get("engine", ""), cpu_seconds=float(extra.get("cpu_seconds", 0.0)),
            max_score_declared=float(data.get("max_score", 0.0)),
            variant=extra.get("variant"),
        )
