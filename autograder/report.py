"""Write results to disk: ``<id>/results.json`` and ``grades.csv``, always atomically.

A reader (a person, Gradescope, an LMS import, a resumed batch) never sees a
half-written file: each file is written beside its target and renamed over it.
"""

from __future__ import annotations

import csv
import io
import json
import os
import tempfile
from pathlib import Path
from typing import Iterable, Sequence

from autograder.results import SubmissionResult

RESULTS_NAME = "results.json"


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old or the new file, never half."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_result(folder: Path, result: SubmissionResult) -> Path:
    """Write ``folder/results.json`` (Gradescope format) atomically."""
    path = folder / RESULTS_NAME
    atomic_write_text(path, json.dumps(result.to_dict(), indent=2, ensure_ascii=False))
    return path


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
