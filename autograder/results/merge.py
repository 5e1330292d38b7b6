"""Merge the results folders of a job array's shards into one class folder.

Each machine of a job array grades its shard (``autograder grade ... --shard K/N``)
into its own folder; ``autograder merge`` copies every ``<id>/`` folder into one
and rebuilds ``grades.csv`` and the summary from all of them, so the merged
folder is the one a single machine would have written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from autograder.errors import UsageError
from autograder.results.files import atomic_write_bytes
from autograder.results.model import SubmissionResult
from autograder.results.store import RESULTS_NAME, read_result, write_grades
from autograder.results.summary import write_summary


@dataclass(frozen=True)
class MergeRun:
    """What a merge did: the merged results, sorted by id."""

    results: tuple[SubmissionResult, ...]
    sources: tuple[Path, ...]


def _result_folders(folder: Path) -> dict[str, tuple[Path, SubmissionResult]]:
    if not folder.is_dir():
        raise UsageError(f"{str(folder)!r} is not a results folder; give the --out folders "
                         "of `autograder grade --shard K/N` runs.")
    found = {}
    for entry in sorted(p for p in folder.iterdir() if p.is_dir()):
        result = read_result(entry)
        if result is not None:
            found[entry.name] = (entry, result)
    return found


def _pick(sub_id: str, candidates: list[tuple[Path, SubmissionResult]]) -> tuple[Path, SubmissionResult]:
    """One folder per id; the same id in two shards must hold the same grading."""
    first = candidates[0]
    for other in candidates[1:]:
        if other[1].key != first[1].key or other[1].to_dict() != first[1].to_dict():
            if first[1].outcome == "error" and other[1].outcome != "error":
                first = other
            elif other[1].outcome == "error":
                continue
            else:
                raise UsageError(
                    f"Submission {sub_id!r} has different results in {str(first[0])!r} and "
                    f"{str(other[0])!r}; were the shards graded with different checks or "
                    "files? Grade it again into one of them, then merge.")
    return first


def _copy_folder(source: Path, target: Path) -> None:
    """Copy every file of ``source`` into ``target`` atomically, ``results.json`` last."""
    files = sorted(p for p in source.rglob("*") if p.is_file() and not p.name.endswith(".tmp"))
    files.sort(key=lambda p: p.name == RESULTS_NAME)
    for path in files:
        atomic_write_bytes(target / path.relative_to(source), path.read_bytes())


def merge_results(folders: Sequence[Path], *, out: Path, title: str | None = None) -> MergeRun:
    """Copy every result of ``folders`` into ``out``; rewrite ``grades.csv`` and the summary.

    Results already in ``out`` stay (so ``out`` may be one of the shards, or the
    class folder); an id graded identically in two folders is copied once; an
    "error" result gives way to a real one.

    Raises
    ------
    UsageError
        A folder is missing, the folders hold different assignments, or one id
        has two different results.
    """
    out = Path(out)
    by_id: dict[str, list[tuple[Path, SubmissionResult]]] = {}
    sources = [Path(f) for f in folders]
    for folder in [*sources, *([out] if out.is_dir() else [])]:
        for sub_id, found in _result_folders(folder).items():
            by_id.setdefault(sub_id, []).append(found)
    names = {r.assignment for group in by_id.values() for _, r in group if r.assignment}
    if len(names) > 1:
        raise UsageError(f"The folders hold results of several assignments ({', '.join(sorted(names))}); "
                         "merge the shards of one assignment at a time.")
    merged = []
    for sub_id in sorted(by_id):
        folder, result = _pick(sub_id, by_id[sub_id])
        if folder.resolve() != (out / sub_id).resolve():
            _copy_folder(folder, out / sub_id)
        merged.append(result)
    out.mkdir(parents=True, exist_ok=True)
    assignment = names.pop() if names else ""
    write_grades(out, merged)
    write_summary(out, merged, title=title or assignment, assignment=assignment)
    return MergeRun(results=tuple(merged), sources=tuple(sources))


__all__ = ["MergeRun", "merge_results"]
