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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

from tqdm import tqdm

from autograder.engine.assignment import Assignment
from autograder.engine.grader import GradingOptions, client_key, error_result
from autograder.engine.slot import GradingSlot
from autograder.engine.submission import IGNORED_FOLDERS
from autograder.errors import UsageError
from autograder.results.model import SubmissionResult
from autograder.results.store import read_result, refresh_feedback, write_grades, write_submission
from autograder.results.summary import Elsewhere, write_summary
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
    #: (id, file) of submissions not graded because the id's result is another file's
    conflicts: tuple[tuple[str, str], ...] = ()

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


def collect_submissions(paths: Iterable[Path], assignment: str | None = None) -> list[Path]:
    """The submissions in ``paths``: notebooks, zips, nbgrader's assignment folders and
    GitHub Classroom's repositories (:func:`classroom_repositories`).

    A folder laid out as nbgrader's ``submitted/<student>/<assignment>/`` (a folder named
    ``submitted``, or one with a ``<student>/<assignment>`` folder inside) gives one
    submission per student: the folder named ``assignment``; other assignments' folders
    are left alone. Any other folder gives the notebooks and zips below it. Explicit
    files are kept as given.
    """
    found: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir() and not path.is_symlink():
            found += _submissions_below(path, assignment)
        elif path.exists() or path.is_symlink():
            found.append(path)
        else:
            raise UsageError(f"Submission {str(path)!r} does not exist; pass a notebook, a zip "
                             "or a folder of them.")
    # Absolute, never resolved: a link stays a link (and is refused with a result
    # saying why) instead of becoming the file it points to under another id.
    unique = list(dict.fromkeys(Path(os.path.abspath(p)) for p in found))
    if not unique:
        where = (f"; in nbgrader's layout, the folders submitted/<student>/{assignment}/"
                 if assignment else "")
        raise UsageError("No notebooks (*.ipynb) or zips were found in the submissions "
                         f"given{where}.")
    return unique


def _submissions_below(folder: Path, assignment: str | None) -> list[Path]:
    if "submitted" not in (folder.name, folder.parent.name):  # nbgrader's names come first
        if folder.parent.name.endswith(CLASSROOM_SUFFIX):
            return [folder]  # one student's repository of GitHub Classroom's layout
        repos = classroom_repositories(folder)
        if repos:
            return repos + _loose_files(folder)
    if assignment is not None:
        if folder.name == assignment and folder.parent.parent.name == "submitted":
            return [folder]  # submitted/<student>/<assignment>/ itself
        if folder.parent.name == "submitted" and (folder / assignment).is_dir():
            return [folder / assignment]  # one student's folder
        students = [d for d in sorted(folder.iterdir())
                    if d.is_dir() and not d.is_symlink() and d.name not in IGNORED_FOLDERS]
        if folder.name == "submitted" or any((d / assignment).is_dir() for d in students):
            return [d / assignment for d in students if (d / assignment).is_dir()
                    and not (d / assignment).is_symlink()] + _loose_files(folder)
    return _files_below(folder, assignment)


def _loose_files(folder: Path) -> list[Path]:
    return [p for p in sorted(folder.iterdir()) if not p.is_dir() and _is_submission(p.name)]


def _is_submission(name: str) -> bool:
    return name.endswith(".ipynb") or name.lower().endswith(".zip")


def _files_below(folder: Path, assignment: str | None = None) -> list[Path]:
    """Notebooks and zips under ``folder``, links included, without following linked folders;
    a ``submitted`` folder below is read as nbgrader's layout (with ``assignment``)."""
    found = []
    for directory, subdirs, files in os.walk(folder, followlinks=False):
        if assignment is not None and "submitted" in subdirs:
            subdirs.remove("submitted")
            found += _submissions_below(Path(directory, "submitted"), assignment)
        subdirs[:] = sorted(d for d in subdirs if d not in IGNORED_FOLDERS)
        for name in [d for d in subdirs if d.endswith(CLASSROOM_SUFFIX)]:
            subdirs.remove(name)  # GitHub Classroom's folder further down
            found += _submissions_below(Path(directory, name), assignment)
        found += [Path(directory, name) for name in sorted(files) if _is_submission(name)]
    return found


#: the suffix of the folder ``gh classroom clone student-repos`` clones into
CLASSROOM_SUFFIX = "-submissions"


def is_repository(folder: Path) -> bool:
    """True for a git working tree (a ``.git`` folder, or the ``.git`` file of a worktree)."""
    return folder.is_dir() and not folder.is_symlink() and os.path.lexists(folder / ".git")


def classroom_repositories(folder: Path) -> list[Path]:
    """The student repositories of GitHub Classroom's layout in ``folder``, else ``[]``.

    ``gh classroom clone student-repos`` clones every accepted assignment into
    ``<slug>-submissions/<slug>-<username>/`` (the repository's name; see
    github/gh-classroom, ``clone/student-repos``). A folder is read that way when its
    name ends in ``-submissions`` or one of its folders is a git repository; then each
    of its folders (repository or not: a download without ``.git``) is one submission.
    """
    if not folder.is_dir() or folder.is_symlink():
        return []
    subdirs = [d for d in sorted(folder.iterdir())
               if d.is_dir() and not d.is_symlink() and d.name not in IGNORED_FOLDERS]
    if folder.name.endswith(CLASSROOM_SUFFIX) or any(is_repository(d) for d in subdirs):
        return subdirs
    return []


def classroom_username(repo: Path) -> str:
    """The username in a Classroom repository's folder name ``<slug>-<username>``.

    The slug comes from the folder the repositories were cloned into
    (``<slug>-submissions``); otherwise it is the longest prefix ending in ``-`` shared
    by all the repositories beside it (GitHub usernames never hold ``--``, a slug may
    hold ``-``). A folder the prefix does not fit keeps its whole name.
    """
    parent = repo.parent
    if parent.name.endswith(CLASSROOM_SUFFIX) and len(parent.name) > len(CLASSROOM_SUFFIX):
        prefix = parent.name[:-len(CLASSROOM_SUFFIX)] + "-"
    else:
        siblings = [d.name for d in parent.iterdir() if d.is_dir() and is_repository(d)]
        shared = os.path.commonprefix(siblings) if len(siblings) > 1 else ""
        prefix = shared[:shared.rfind("-") + 1]
    name = repo.name
    return name[len(prefix):] if prefix and name.startswith(prefix) and name != prefix else name


#: the characters an id keeps as they are; every other is written ``~XX`` (UTF-8, hex)
_SAFE = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789._-")
#: joins the parts of an id that needs more than a name; never in an escaped name
_JOIN = "+"


def escape_id(name: str) -> str:
    """``name`` as an id: safe characters kept, others (``~`` too) written ``~XX``.

    Injective (``alice``, ``alice!`` and ``alice `` stay three ids: ``alice``,
    ``alice~21``, ``alice~20``), never hidden (a leading ``.`` is escaped) and never
    a path (``/`` is escaped).
    """
    out = []
    for k, char in enumerate(name):
        if char in _SAFE and not (k == 0 and char == "."):
            out.append(char)
        else:
            out.extend(f"~{b:02X}" for b in char.encode("utf-8", "surrogateescape"))
    return "".join(out) or "~"


def place_name(path: Path) -> str:
    """The name a submission's place gives it: ``<student>`` in nbgrader's layout, the
    username in GitHub Classroom's (:func:`classroom_username`), else the stem.

    nbgrader keeps submissions as ``submitted/<student>/<assignment>/<notebook>.ipynb``;
    the student's folder is what an LMS roster knows, whether one file, one
    assignment folder or the whole ``submitted/`` folder is given.
    """
    parts = path.parts
    if len(parts) >= 4 and parts[-4] == "submitted":
        return parts[-3]
    if path.is_dir() and len(parts) >= 3 and parts[-3] == "submitted":
        return parts[-2]
    if path.is_dir() and (is_repository(path) or path.parent.name.endswith(CLASSROOM_SUFFIX)):
        return classroom_username(path)
    if path.is_dir() and len(parts) >= 2:
        return parts[-2]  # <student>/<assignment>/ outside a folder named submitted
    return path.stem


def assign_ids(paths: Sequence[Path]) -> dict[Path, str]:
    """Readable ids, one per submission, from each one's place (see :func:`place_name`).

    The mapping is injective: a name is escaped (:func:`escape_id`), never
    shortened, so distinct names never share an id. When two submissions have the
    same name, the file's stem and then as many folders as tell them apart are
    joined with ``+`` (never in an escaped name) after the name: ``alice+hull`` and
    ``alice+extra``; ``a/x.ipynb`` and ``b/x.ipynb`` become ``x+a`` and ``x+b``. A name the batch writes itself (``grades.csv``...) gets a
    trailing ``+``.
    """
    ids: dict[Path, str] = {}
    by_name: dict[str, list[Path]] = {}
    for path in paths:
        by_name.setdefault(place_name(path), []).append(path)
    for name, group in by_name.items():
        if len(group) == 1:
            ids[group[0]] = escape_id(name)
            continue
        with_stem = [(name,) if p.stem == name else (name, p.stem) for p in group]
        if len(set(with_stem)) != len(group):
            with_stem = [(name, *_telling_folders(p, group, name)) for p in group]
        ids.update((p, _JOIN.join(map(escape_id, parts))) for p, parts in zip(group, with_stem))
    return {p: i + _JOIN if i.lower() in RESERVED_NAMES else i for p, i in ids.items()}


def _telling_folders(path: Path, group: Sequence[Path], name: str) -> tuple[str, ...]:
    """As many parent folders as it takes to tell ``group`` apart, then the stem unless it
    is ``name``."""
    depth = 1
    while depth < 64 and len({tuple(p.parts[-1 - depth:]) for p in group}) < len(group):
        depth += 1
    return (*path.parts[-1 - depth:-1], *((path.stem,) if path.stem != name else ()))


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


def write_exports(out_dir: Path, assignment: Assignment,
                  given: Mapping[str, str] | None = None) -> tuple[SubmissionResult, ...]:
    """Rewrite ``grades.csv``, ``summary.json`` and ``summary.html``; return the exported results.

    ``given``: this run's submissions (id -> source). Only results of those are
    exported; the folder's other results stay on disk and are listed in the summary
    as no longer submitted, or as a conflict when another file claims their id.
    None: every result in the folder (a folder put together by hand or by a merge).
    """
    results = folder_results(out_dir, assignment.name)
    elsewhere: list[Elsewhere] = []
    if given is not None:
        kept = []
        for result in results:
            if result.id not in given:
                elsewhere.append(Elsewhere(result.id, result.source))
            elif given[result.id] != result.source:
                elsewhere.append(Elsewhere(result.id, result.source, claimed_by=given[result.id]))
            else:
                kept.append(result)
        results = tuple(kept)
    write_grades(out_dir, results)
    write_summary(out_dir, results, title=assignment.title, assignment=assignment.name,
                  elsewhere=elsewhere)
    return results


def claimed_elsewhere(previous: SubmissionResult | None, path: Path,
                      given: Iterable[str]) -> bool:
    """True when ``previous``, the result in ``path``'s id folder, is another file's.

    That file still exists and is not given in this run (when it is, it has an id
    of its own and this folder's result is simply out of date); a result whose file
    was moved or removed is ``path``'s to replace.
    """
    if previous is None or not previous.source or previous.source == str(path):
        return False
    return os.path.lexists(previous.source) and previous.source not in set(given)


class _Bar(tqdm):  # type: ignore[misc]  # tqdm is untyped
    """tqdm's bar without its monitor thread (which tqdm starts even for a bar it hides).

    The thread only refreshes bars that went quiet, and ours moves with every result;
    without it, the batch's process runs one thread and can fork the pool's slot
    processes (see :meth:`autograder.runners.local._PoolFeeder.fork_pool`).
    """

    monitor_interval = 0


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
    paths = collect_submissions(submissions, assignment.name)
    ids = assign_ids(paths)
    given = {ids[p]: str(p) for p in paths}
    if shard is not None:
        paths = [p for p in paths if shard.holds(ids[p])]
    out_dir.mkdir(parents=True, exist_ok=True)
    folder_results(out_dir, assignment.name)  # refuse another assignment's folder before grading
    done: dict[str, SubmissionResult] = {}
    todo: list[Job] = []
    conflicts: list[Path] = []
    for path in paths:
        previous = read_result(out_dir / ids[path])
        if claimed_elsewhere(previous, path, given.values()):
            conflicts.append(path)  # never graded over another file's result
            continue
        key = client_key(path, assignment, options)
        if previous is not None and previous.key == key and previous.outcome != "error":
            if previous.source != str(path):  # the same file, moved: the result follows it
                previous = write_submission(out_dir / ids[path],
                                            replace(previous, source=str(path)),
                                            title=assignment.title)
            done[ids[path]] = previous
            refresh_feedback(out_dir / ids[path], previous, title=assignment.title,
                             deadline=assignment.deadline)
        else:
            todo.append(Job(path, ids[path]))
    paths = [p for p in paths if p not in conflicts]
    reused = len(done)
    bar = _Bar(total=len(paths), initial=reused, unit="nb", desc=assignment.name,
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
    folder = write_exports(out_dir, assignment, given)
    return BatchRun(results=tuple(done[ids[p]] for p in paths), graded=len(todo),
                    reused=reused, seconds=time.perf_counter() - start, folder=folder,
                    other_shards=len(ids) - len(paths) - len(conflicts),
                    conflicts=tuple((ids[p], str(p)) for p in conflicts))
