"""Grade many submissions: unique ids, resume, parallel slots, a progress bar.

Each slot is a separate (trusted) Python process holding one :class:`Grader`
and its warm worker; the batch hands it one file at a time. Any engine that can
call :func:`grade_one` per file (Dask, Ray, a queue) could replace the process
pool here.
"""

from __future__ import annotations

import multiprocessing
import os
import re
import sys
import traceback
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

from tqdm import tqdm

from autograder.assignment import Assignment, load_assignment
from autograder.errors import UsageError
from autograder.feedback import FEEDBACK_NAME, write_feedback
from autograder.grading import Grader, GradingOptions, submission_key, _file_sha256
from autograder.report import RESULTS_NAME, read_result, write_grades, write_result
from autograder.results import SubmissionResult
from autograder.summary import write_summary


@dataclass(frozen=True)
class BatchReport:
    """What a batch run did."""

    results: tuple[SubmissionResult, ...]
    graded: int
    reused: int
    seconds: float

    @property
    def failed(self) -> tuple[SubmissionResult, ...]:
        """Submissions the grader itself could not grade (outcome "error")."""
        return tuple(r for r in self.results if r.outcome == "error")


def collect_submissions(paths: Iterable[Path]) -> list[Path]:
    """Expand folders to the notebooks inside them; keep explicit files as given."""
    found: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir():
            found += sorted(p for p in path.rglob("*.ipynb")
                            if ".ipynb_checkpoints" not in p.parts and p.is_file())
        elif path.exists():
            found.append(path)
        else:
            raise UsageError(f"Submission {str(path)!r} does not exist; pass a notebook "
                             "file or a folder of notebooks.")
    unique = list(dict.fromkeys(p.resolve() for p in found))
    if not unique:
        raise UsageError("No notebooks (*.ipynb) were found in the submissions given.")
    return unique


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.") or "submission"


def assign_ids(paths: Sequence[Path]) -> dict[Path, str]:
    """Readable unique ids: the file stem, plus the folders that tell colliding stems apart.

    ``submitted/alice/hull/hull.ipynb`` and ``submitted/bob/hull/hull.ipynb``
    become ``alice-hull`` and ``bob-hull``.
    """
    ids: dict[Path, str] = {}
    by_stem: dict[str, list[Path]] = {}
    for path in paths:
        by_stem.setdefault(path.stem, []).append(path)
    for stem, group in by_stem.items():
        if len(group) == 1:
            ids[group[0]] = _slug(stem)
            continue
        depth = 1
        while depth < 64:
            labels = [tuple(p.parts[-1 - depth:-1]) for p in group]
            if len(set(labels)) == len(group):
                break
            depth += 1
        for path in group:
            parts = [q for q in path.parts[-1 - depth:-1]] + [stem]
            deduped = [q for i, q in enumerate(parts) if i == 0 or q != parts[i - 1]]
            ids[path] = _slug("-".join(deduped))
    taken: dict[str, int] = {}
    for path in paths:  # a last resort for ids that still collide after slugging
        base = ids[path]
        taken[base] = taken.get(base, 0) + 1
        if taken[base] > 1:
            ids[path] = f"{base}-{taken[base]}"
    return ids


# One Grader per pool process: the warm worker is the point of the pool. This is the
# package's only module-level state, and it lives only in pool processes.
_GRADER: Grader | None = None


def _init_slot(assignment_root: str, options: GradingOptions, counter: Any) -> None:
    global _GRADER
    with counter.get_lock():
        slot = counter.value
        counter.value += 1
    _GRADER = Grader(load_assignment(Path(assignment_root)), options, slot=slot)


def grade_one(grader: Grader, path: Path, sub_id: str, out_dir: Path) -> SubmissionResult:
    """Grade one file into ``out_dir/<id>/``; a grader failure becomes an "error" result.

    ``results.json`` is written first, then ``feedback.html`` beside it, whatever
    the outcome.
    """
    folder = out_dir / sub_id
    try:
        result = grader.grade(path, id=sub_id, out_dir=folder)
    except Exception as exc:  # the grader's own failure: record it, never lose the file
        result = error_result(grader.assignment, path, sub_id, exc)
        write_result(folder, result)
    write_feedback(folder, result, title=grader.assignment.title)
    return result


def refresh_feedback(folder: Path, result: SubmissionResult, title: str) -> None:
    """Write ``feedback.html`` for a reused result when it is missing or older than its result."""
    page, data = folder / FEEDBACK_NAME, folder / RESULTS_NAME
    try:
        fresh = page.stat().st_mtime_ns >= data.stat().st_mtime_ns
    except OSError:
        fresh = False
    if not fresh:
        write_feedback(folder, result, title=title)


def _grade_in_slot(path: str, sub_id: str, out_dir: str) -> dict[str, Any]:
    assert _GRADER is not None
    return grade_one(_GRADER, Path(path), sub_id, Path(out_dir)).to_dict()


def error_result(assignment: Assignment, path: Path, sub_id: str, exc: BaseException) -> SubmissionResult:
    detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    return SubmissionResult(
        id=sub_id, source=str(path), assignment=assignment.name, key="",
        sha256=_file_sha256(path), outcome="error",
        output=f"The grader failed on this submission ({detail}); it will be regraded on the next run.",
        tests=(), execution_time=0.0, seed=0)


def grade_batch(assignment: Assignment, submissions: Sequence[Path], out_dir: Path, *,
                jobs: int | None = None, options: GradingOptions | None = None,
                progress: bool | None = None,
                on_result: Callable[[SubmissionResult], None] | None = None) -> BatchReport:
    """Grade every submission into ``out_dir``, reusing results whose key is unchanged.

    Writes ``<id>/results.json`` and ``<id>/feedback.html`` as each submission
    finishes, then ``grades.csv``, ``summary.json`` and ``summary.html`` from
    every result (reused ones included).
    """
    import time

    start = time.perf_counter()
    options = options or GradingOptions()
    paths = collect_submissions(submissions)
    ids = assign_ids(paths)
    out_dir.mkdir(parents=True, exist_ok=True)
    done: dict[str, SubmissionResult] = {}
    todo: list[Path] = []
    for path in paths:
        previous = read_result(out_dir / ids[path])
        key = submission_key(_file_sha256(path), assignment, options)
        if previous is not None and previous.key == key and previous.outcome != "error":
            done[ids[path]] = previous
            refresh_feedback(out_dir / ids[path], previous, assignment.title)
        else:
            todo.append(path)
    reused = len(done)
    jobs = max(1, min(jobs or os.cpu_count() or 1, len(todo) or 1))
    bar = tqdm(total=len(paths), initial=reused, unit="nb", desc=assignment.name,
               disable=(not sys.stderr.isatty()) if progress is None else not progress)

    def finished(result: SubmissionResult) -> None:
        done[result.id] = result
        bar.update(1)
        if on_result is not None:
            on_result(result)

    if jobs == 1:
        with Grader(assignment, options) as grader:
            for path in todo:
                finished(grade_one(grader, path, ids[path], out_dir))
    else:
        _run_pool(assignment, options, jobs, [(p, ids[p]) for p in todo], out_dir, finished)
    bar.close()
    results = tuple(done[ids[p]] for p in paths)
    write_grades(out_dir, results)
    write_summary(out_dir, results, title=assignment.title, assignment=assignment.name)
    return BatchReport(results=results, graded=len(todo), reused=reused,
                       seconds=time.perf_counter() - start)


def _run_pool(assignment: Assignment, options: GradingOptions, jobs: int,
              work: list[tuple[Path, str]], out_dir: Path,
              finished: Callable[[SubmissionResult], None]) -> None:
    """Run ``work`` on ``jobs`` slots; if a slot process dies, rebuild and retry once."""
    context = multiprocessing.get_context("spawn")
    attempts: dict[str, int] = {}
    pending = list(work)
    while pending:
        counter = context.Value("i", 0)
        broken: list[tuple[Path, str]] = []
        with ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=_init_slot,
                                 initargs=(str(assignment.root), options, counter)) as pool:
            futures: dict[Future[dict[str, Any]], tuple[Path, str]] = {
                pool.submit(_grade_in_slot, str(p), i, str(out_dir)): (p, i) for p, i in pending}
            for future in as_completed(futures):
                path, sub_id = futures[future]
                try:
                    finished(SubmissionResult.from_dict(future.result()))
                except BrokenProcessPool as exc:
                    attempts[sub_id] = attempts.get(sub_id, 0) + 1
                    if attempts[sub_id] >= 2:
                        result = error_result(assignment, path, sub_id, exc)
                        write_result(out_dir / sub_id, result)
                        write_feedback(out_dir / sub_id, result, title=assignment.title)
                        finished(result)
                    else:
                        broken.append((path, sub_id))
        pending = broken
