"""The one writer of a result folder: ``<id>/results.json``, ``<id>/feedback.html``, ``grades.csv``.

Every runner (the batch, the local pool, a Dask node's client, the service's
grader processes and its Dask dispatcher, the Gradescope run) writes a
submission's folder through :func:`write_submission`, so the folder's layout is
known here alone. A reader (a person, Gradescope, an LMS import, a resumed batch)
never sees a half-written file (:mod:`autograder.results.files`).
"""

from __future__ import annotations

import csv
import io
import datetime as dt
import json
from pathlib import Path
from typing import Iterable, Sequence

from autograder.results.feedback import FEEDBACK_NAME, is_past, write_feedback
from autograder.results.files import atomic_write_text
from autograder.results.model import SubmissionResult

RESULTS_NAME = "results.json"


def write_result(folder: Path, result: SubmissionResult) -> Path:
    """Write ``folder/results.json`` (Gradescope format) atomically."""
    path = folder / RESULTS_NAME
    atomic_write_text(path, json.dumps(result.to_dict(), indent=2, ensure_ascii=False))
    return path


def write_submission(folder: Path, result: SubmissionResult, *, title: str,
                     deadline: dt.datetime | None = None) -> SubmissionResult:
    """Write ``result`` into ``folder``: ``results.json`` first, then ``feedback.html``; return it.

    Pictures and the instructor's log are written into ``folder`` by the checks
    while they run (:class:`~autograder.engine.plugin.CheckContext`); this writes
    what is written once the verdicts are in.
    """
    write_result(folder, result)
    write_feedback(folder, result, title=title, deadline=deadline)
    return result


def refresh_feedback(folder: Path, result: SubmissionResult, *, title: str,
                     deadline: dt.datetime | None = None) -> None:
    """Write ``feedback.html`` for a reused result when it is missing or older than its result,
    or was written before ``deadline`` which has passed since (checks shown after it)."""
    page, data = folder / FEEDBACK_NAME, folder / RESULTS_NAME
    try:
        written = page.stat().st_mtime_ns
        fresh = written >= data.stat().st_mtime_ns
    except OSError:
        written, fresh = 0, False
    if fresh and deadline is not None and is_past(deadline):
        fresh = written >= deadline.timestamp() * 1e9
    if not fresh:
        write_feedback(folder, result, title=title, deadline=deadline)


def read_result(folder: Path) -> SubmissionResult | None:
    """The result stored in ``folder``, or None when absent or unreadable."""
    try:
        data = json.loads((folder / RESULTS_NAME).read_text(encoding="utf-8"))
        return SubmissionResult.from_dict(data)
    except (OSError, ValueError, KeyError, TypeError):
        return None


def check_columns(results: Iterable[SubmissionResult]) -> list[str]:
    """Every check name, in first-seen order, across ``results``."""
    names: dict[str, None] = {}
    for result in results:
        for test in result.tests:
            names.setdefault(test.name, None)
    return list(names)


def grades_csv(results: Sequence[SubmissionResult]) -> str:
    """One row per submission: id, score, max_score, outcome, then each check's score."""
    columns = check_columns(results)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["id", "score", "max_score", "outcome", *columns])
    for result in sorted(results, key=lambda r: r.id):
        scores = {t.name: t.score for t in result.tests}
        writer.writerow([result.id, _num(result.score), _num(result.max_score), result.outcome,
                         *(_num(scores[c]) if c in scores else "" for c in columns)])
    return buffer.getvalue()


def _num(value: float) -> str:
    return f"{value:g}"


def write_grades(out_dir: Path, results: Sequence[SubmissionResult]) -> Path:
    path = out_dir / "grades.csv"
    atomic_write_text(path, grades_csv(results))
    return path
