"""Write results to disk: ``<id>/results.json`` and ``grades.csv``, always atomically.

A reader (a person, Gradescope, an LMS import, a resumed batch) never sees a
half-written file: each file is written beside its target and renamed over it.
"""

from __future__ import annotations

import csv
import io
import json
import os
import secrets
from pathlib import Path
from typing import Iterable, Sequence

from autograder.results import SubmissionResult

RESULTS_NAME = "results.json"


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old or the new file, never half."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically; the file's mode follows the user's umask.

    The temporary file is created with ``os.open(..., 0o666)`` rather than
    :func:`tempfile.mkstemp` (always 0600), so the kernel applies the umask as
    for any other file the user writes, and a class folder stays readable by
    the course's group when the umask says so.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
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
