"""Grade many submissions: unique ids, resume, a backend, a progress bar, the class folder.

The results folder is the unit of export: whatever this run graded, ``grades.csv``
and the summary are rebuilt from every ``<id>/results.json`` in the folder, so
grading one late notebook into the class's folder keeps everyone else's row.
Where the gradings run is a backend's business (:mod:`autograder.runners.backends`: the
local process pool, or a Dask cluster).
"""

from __future__ import annotations

import hashlib
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

from tqdm import tqdm

from autograder.engine.assignment import Assignment
from autograder.engine.grader import GradingOptions, client_key, error_result, group_submissions
from autograder.engine.slot import GradingSlot
from autograder.errors import UsageError
from autograder.results.model import SubmissionResult
from autograder.results.store import read_result, refresh_feedback, write_grades, write_submission
from autograder.results.summary import write_summary
from autograder.runners.backends import make_backend
from autograder.runners.jobs import DaskSpec, Job

#: files and folders the batch itself writes at the top of a results folder; never ids
RESERVED_NAMES = frozenset({"grades.csv", "summary.html", "summary.json", "junit.xml",
                            "images", "feedback.html", "results.json"})


@dataclass(frozen=True)
class BatchRun:
    """What a batch run did.

    ``results`` holds this run's submissions (graded or reused); ``folder`` every
    result of the assignment in the results folder, from which the exports were
    written (this run's and earlier ones').
    """

    results: tuple[SubmissionResult, ...]
    graded: int
    reused: int
    seconds: float
    folder: tuple[SubmissionResult, ...] = ()
    #: submissions left to other shards (``--shard K/N``)
    other_shards: int = 0

    @property
    def failed(self) -> tuple[SubmissionResult, ...]:
        """Submissions the grader itself could not grade (outcome "error")."""
        return tuple(r for r in self.results if r.outcome == "error")


@dataclass(frozen=True)
class Shard:
    """``K/N``: the submissions whose id hashes to K modulo N (0 <= K < N).

    The hash is SHA-256 of the id, so every machine of a job array picks the
    same submissions from the same folder, whatever its Python or its order.
    """

    index: int
    count: int

    def __post_init__(self) -> None:
        if not (self.count >= 1 and 0 <= self.index < self.count):
            raise UsageError(f"--shard {self.index}/{self.count}: write K/N with 0 <= K < N "
                             "(e.g. 0/3, 1/3 and 2/3 for three machines).")

    @classmethod
    def parse(cls, text: str) -> "Shard":
        match = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
        if match is None:
            raise UsageError(f"--shard {text!r}: write K/N, e.g. 0/3 (K counts from 0).")
        return cls(int(match[1]), int(match[2]))

    def holds(self, sub_id: str) -> bool:
        value = int.from_bytes(hashlib.sha256(sub_id.encode("utf-8")).digest()[:8], "big")
        return value % self.count == self.index


def collect_submissions(paths: Iterable[Path]) -> list[Path]:
    """Expand folders to the notebooks inside them; keep explicit files as given."""
    found: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir() and not path.is_symlink():
            found += _notebooks_below(path)
        elif path.exists() or path.is_symlink():
            found.append(path)
        else:
            raise UsageError(f"Submission {str(path)!r} does not exist; pass a notebook "
                             "file or a folder of notebooks.")
    # Absolute, never resolved: a link stays a link (and is refused with a result
    # saying why) instead of becoming the file it points to under another id.
    unique = list(dict.fromkeys(Path(os.path.abspath(p)) for p in found))
    if not unique:
        raise UsageError("No notebooks (*.ipynb) were found in the submissions given.")
    return unique


def _notebooks_below(folder: Path) -> list[Path]:
    """``*.ipynb`` entries under ``folder``, links included, without following linked folders."""
    found = []
    for directory, subdirs, files in os.walk(folder, followlinks=False):
        subdirs[:] = sorted(d for d in subdirs if d != ".ipynb_checkpoints")
        found += [Path(directory, name) for name in sorted(files) if name.endswith(".ipynb")]
    return found


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.") or "submission"


def place_name(path: Path) -> str:
    """The name a file's place gives it: ``<student>`` in nbgrader's layout, else the stem.

    nbgrader keeps submissions as ``submitted/<student>/<assignment>/<notebook>.ipynb``;
    the student's folder is what an LMS roster knows, whether one file or the
    whole ``submitted/`` folder is given.
    """
    parts = path.parts
    if len(parts) >= 4 and parts[-4] == "submitted":
        return parts[-3]
    if len(parts) >= 3 and parts[-3] == "submitted" and path.is_dir():  # a folder of notebooks
        return parts[-2]
    return path.stem


def assign_ids(paths: Sequence[Path]) -> dict[Path, str]:
    """Readable unique ids from each file's place (see :func:`place_name`).

    When names collide, the stem and then the folders that tell the files apart
    are added: two notebooks of one student become ``alice-hull`` and
    ``alice-extra``; ``a/x.ipynb`` and ``b/x.ipynb`` become ``a-x`` and ``b-x``.
    An id is never a name the batch writes itself (``grades.csv``, ``summary.html``...).
    """
    ids: dict[Path, str] = {}
    by_name: dict[str, list[Path]] = {}
    for path in paths:
        by_name.setdefault(place_name(path), []).append(path)
    for name, group in by_name.items():
        if len(group) == 1:
            ids[group[0]] = _slug(name)
            continue
        with_stem = [name if p.stem == name else f"{name}-{p.stem}" for p in group]
        if len(set(with_stem)) == len(group):
            ids.update(zip(group, map(_slug, with_stem)))
            continue
        ids.update(_by_folders(group))
    taken: dict[str, int] = {}
    for path in paths:  # a last resort for ids that still collide after slugging
        base = ids[path]
        if base.lower() in RESERVED_NAMES:
            base = f"{base}-submission"
        taken[base] = taken.get(base, 0) + 1
        ids[path] = base if taken[base] == 1 else f"{base}-{taken[base]}"
    return ids


def _by_folders(group: Sequence[Path]) -> dict[Path, str]:
    """Ids from the stem and as many parent folders as it takes to tell ``group`` apart."""
    depth = 1
    while depth < 64:
        labels = [tuple(p.parts[-1 - depth:-1]) for p in group]
        if len(set(labels)) == len(group):
            break
        depth += 1
    ids = {}
    for path in group:
        parts = list(path.parts[-1 - depth:-1]) + [path.stem]
        deduped = [q for i, q in enumerate(parts) if i == 0 or q != parts[i - 1]]
        ids[path] = _slug("-".join(deduped))
    return ids


def folder_results(out_dir: Path, assignment: str) -> tuple[SubmissionResult, ...]:
    """Every result of ``assignment`` in ``out_dir`` (``<id>/results.json``), sorted by id.

    Raises
    ------
    UsageError
        When the folder holds results of another assignment: one folder per
        assignment, so that its ``grades.csv`` is one gradebook column.
    """
    found = []
    for folder in sorted(p for p in out_dir.iterdir() if p.is_dir()) if out_dir.is_dir() else ():
        result = read_result(folder)
        if result is None:
            continue
        if result.assignment and result.assignment != assignment:
            raise UsageError(
                f"{str(out_dir)!r} holds results of assignment {result.assignment!r} "
                f"({folder.name}/results.json); grade {assignment!r} into a folder of its own.")
        found.append(result)
    return tuple(found)


def write_exports(out_dir: Path, assignment: Assignment) -> tuple[SubmissionResult, ...]:
    """Rewrite ``grades.csv``, ``summary.json`` and ``summary.html`` from every result in the folder."""
    results = folder_results(out_dir, assignment.name)
    write_grades(out_dir, results)
    write_summary(out_dir, results, title=assignment.title, assignment=assignment.name)
    return results


def grade_batch(assignment: Assignment, submissions: Sequence[Path], out_dir: Path, *,
                jobs: int | None = None, options: GradingOptions | None = None,
                progress: bool | None = None,
                on_result: Callable[[SubmissionResult], None] | None = None,
                dask: DaskSpec | None = None, shard: Shard | None = None,
                started_slot: GradingSlot | None = None) -> BatchRun:
    """Grade every submission into ``out_dir``, reusing results whose key is unchanged.

    Writes ``<id>/results.json`` and ``<id>/feedback.html`` as each submission
    finishes, then ``grades.csv``, ``summary.json`` and ``summary.html`` from
    every result in ``out_dir`` (earlier runs' included). ``dask`` sends the
    gradings to a Dask cluster instead of the local pool of ``jobs`` processes;
    ``shard`` keeps only the submissions of that shard. ``started_slot``, a slot started
    ahead, becomes the local pool's slot 0 (its owner closes it if nothing is graded).
    """
    start = time.perf_counter()
    if dask is not None and jobs is not None:
        raise UsageError("--jobs sets the local pool's size; with --dask the cluster's grading "
                         "slots set how many run at once (local:N, or `autograder worker --slots N`).")
    options = options or GradingOptions()
    paths = group_submissions(assignment, collect_submissions(submissions))
    ids = assign_ids(paths)
    if shard is not None:
        paths = [p for p in paths if shard.holds(ids[p])]
    out_dir.mkdir(parents=True, exist_ok=True)
    folder_results(out_dir, assignment.name)  # refuse another assignment's folder before grading
    done: dict[str, SubmissionResult] = {}
    todo: list[Job] = []
    for path in paths:
        previous = read_result(out_dir / ids[path])
        key = client_key(path, assignment, options)
        if previous is not None and previous.key == key and previous.outcome != "error":
            done[ids[path]] = previous
            refresh_feedback(out_dir / ids[path], previous, title=assignment.title)
        else:
            todo.append(Job(path, ids[path]))
    reused = len(done)
    bar = tqdm(total=len(paths), initial=reused, unit="nb", desc=assignment.name,
               disable=(not sys.stderr.isatty()) if progress is None else not progress)
    if todo:  # 0% for seconds otherwise: the slots import numpy, scipy and the checks first
        bar.set_postfix_str("starting the grading workers")

    def finished(result: SubmissionResult) -> None:
        done[result.id] = result
        if bar.postfix:
            bar.set_postfix_str("", refresh=False)
        bar.update(1)
        if on_result is not None:
            on_result(result)

    try:
        if todo:
            make_backend(jobs=jobs, dask=dask, started_slot=started_slot).run(assignment, options, todo,
                                                                  out_dir, finished)
    finally:
        bar.close()
    missing = [job for job in todo if job.id not in done]
    for job in missing:  # a backend must answer for every job; if not, say so as an error
        result = error_result(assignment, job.path, job.id, "no result came back for it")
        finished(write_submission(out_dir / job.id, result, title=assignment.title))
    folder = write_exports(out_dir, assignment)
    return BatchRun(results=tuple(done[ids[p]] for p in paths), graded=len(todo),
                       reused=reused, seconds=time.perf_counter() - start, folder=folder,
                       other_shards=len(ids) - len(paths))
