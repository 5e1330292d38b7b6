"""Whether a submitted notebook is this assignment's, and handed in as meant.

A notebook released by nbgrader keeps the instructor notebook's cell ids
(nbformat 4.5) and ``metadata.nbgrader.grade_id`` of its cells, so these say
which assignment it came from: :func:`identify` compares them with the
instructor notebooks of this assignment and of the assignments beside it (the
other folders of its ``assignments/`` folder). A notebook without them (metadata
stripped, a notebook written from scratch) is this assignment's unless its file
name is another assignment's notebook name.

What it finds is an :class:`Identity`: the other assignment it belongs to (the
submission is then ungradable: "this is the spline_car notebook, not hull"), and
notes for a person (the released template handed in untouched; answer cells
deleted).
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import nbformat

from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.notebook import Notebook
from autograder.engine.released import released_notebook
from autograder.errors import AssignmentError
from autograder.results.model import SUBMISSION_NOTE

_LOG = logging.getLogger("autograder.engine.identify")


@dataclass(frozen=True)
class Fingerprint:
    """What tells one assignment's notebook from another's."""

    name: str
    #: file names of its instructor notebooks
    files: tuple[str, ...]
    #: cell ids and grade ids of its code cells
    marks: frozenset[str]
    #: grade ids of its answer cells (nbgrader solution cells), in notebook order
    answers: tuple[str, ...]
    #: grade ids of its graded test cells
    tests: tuple[str, ...]
    #: grade_id -> the released source of each answer cell ("" when nbgrader is missing)
    stubs: tuple[tuple[str, str], ...]
    #: the released notebook's non-blank code, stripped, in order (() when nbgrader is missing)
    template: tuple[str, ...]


@dataclass(frozen=True)
class Identity:
    """What :func:`identify` found; ``other`` is "" for a notebook of this assignment."""

    other: str = ""
    problem: str = ""
    notes: tuple[str, ...] = ()


def identify(notebook: Notebook, assignment: Assignment, *,
             others: Sequence[Fingerprint] | None = None) -> Identity:
    """Whether ``notebook`` belongs to ``assignment`` (see the module notes).

    ``others``: the fingerprints of the other known assignments (default: the
    assignments beside ``assignment``'s folder).
    """
    ours = fingerprint(assignment)
    marks = _marks(notebook)
    mine = len(marks & ours.marks)
    answered = {c.grade_id for c in notebook.cells} & set(ours.answers)
    if not answered:  # only then the neighbours are read (an answered notebook is ours)
        others = known_fingerprints(assignment) if others is None else others
        best = max(others, key=lambda f: len(marks & f.marks), default=None)
        theirs = len(marks & best.marks) if best is not None else 0
        if theirs > mine:
            return _wrong(best.name, ours.name, "its cells are that assignment's")
        if not mine and not theirs:
            by_name = [f for f in others if notebook.path.name in f.files
                       and notebook.path.name not in ours.files]
            if by_name:
                return _wrong(by_name[0].name, ours.name, "it has that assignment's file name")
    notes = []
    if _untouched(notebook, ours):
        notes.append(f"{SUBMISSION_NOTE}this is the released template of {ours.name}, "
                     "unchanged: no answer was written (or the wrong file was handed in).")
    if answered or mine:
        present = {c.grade_id for c in notebook.cells}
        gone = [g for g in ours.answers + ours.tests if g not in present]
        if gone:
            notes.append(f"{SUBMISSION_NOTE}cell(s) {', '.join(f'`{g}`' for g in gone)} of the "
                         f"released notebook are missing (deleted?); checks of what they "
                         "defined score zero.")
    return Identity(notes=tuple(notes))


def _wrong(other: str, ours: str, why: str) -> Identity:
    return Identity(other=other, problem=(
        f"this is the {other} notebook, not {ours} ({why}). Hand in your {ours} notebook, "
        f"and the {other} notebook to {other}."))


def _marks(notebook: Notebook) -> frozenset[str]:
    found = set()
    for cell in notebook.cells:
        found.update(m for m in (cell.cell_id, cell.grade_id) if m)
    return frozenset(found)


def _untouched(notebook: Notebook, ours: Fingerprint) -> bool:
    """Every answer cell as released, or all the code as released (metadata stripped)."""
    code = tuple(c.source.strip() for c in notebook.cells if c.source.strip())
    if ours.template and code == ours.template:
        return True
    stubs = dict(ours.stubs)
    answers = [c for c in notebook.cells if c.grade_id in stubs and stubs[c.grade_id]]
    return bool(answers) and len({c.grade_id for c in answers}) == len(stubs) and all(
        c.source.strip() == stubs[c.grade_id or ""] for c in answers)


def fingerprint(assignment: Assignment) -> Fingerprint:
    """The fingerprint of ``assignment`` (cached while its notebooks are unchanged)."""
    stamps = tuple((str(p), _mtime(p)) for p in assignment.notebooks)
    return _fingerprint(assignment.name, stamps)


def known_fingerprints(assignment: Assignment) -> tuple[Fingerprint, ...]:
    """Fingerprints of the assignments beside ``assignment`` (folders with ``assignment.toml``)."""
    parent = assignment.root.parent
    found = []
    for folder in sorted(parent.iterdir()) if parent.is_dir() else ():
        if folder == assignment.root or not (folder / "assignment.toml").is_file():
            continue
        name, other = _neighbour(folder)
        if other is not None and name != assignment.name:
            found.append(other)
    return tuple(found)


#: folder -> (the stamps it was read at, its notebooks, its name, its fingerprint): a
#: grader reads its neighbours once, not for every submission (about 7 ms of CPU each)
_NEIGHBOURS: dict[str, tuple[tuple[int, ...], tuple[Path, ...], str, Fingerprint | None]] = {}


def _neighbour(folder: Path) -> tuple[str, Fingerprint | None]:
    """The name and fingerprint of the assignment in ``folder`` (None: it cannot be read,
    which is its own instructor's problem), read again once its ``assignment.toml`` or
    one of its notebooks changed."""
    toml = folder / "assignment.toml"
    kept = _NEIGHBOURS.get(str(folder))
    if kept is not None and kept[0] == _stamps(toml, kept[1]):
        return kept[2], kept[3]
    before = _mtime(toml)
    try:
        other = load_assignment(folder)
    except AssignmentError:
        notebooks: tuple[Path, ...] = ()
        name, found = "", None
    else:
        notebooks, name, found = tuple(other.notebooks), other.name, fingerprint(other)
    stamps = _stamps(toml, notebooks)
    if stamps[0] == before:  # not kept when it changed while it was read
        _NEIGHBOURS[str(folder)] = (stamps, notebooks, name, found)
    return name, found


def _stamps(toml: Path, notebooks: tuple[Path, ...]) -> tuple[int, ...]:
    return (_mtime(toml), *(_mtime(p) for p in notebooks))


def _mtime(path: Path) -> int:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return 0


@functools.lru_cache(maxsize=64)
def _fingerprint(name: str, stamps: tuple[tuple[str, int], ...]) -> Fingerprint:
    marks: set[str] = set()
    answers: list[str] = []
    tests: list[str] = []
    stubs: list[tuple[str, str]] = []
    template: list[str] = []
    for path, _ in stamps:
        try:
            nb = nbformat.read(path, as_version=4)
        except (OSError, ValueError) as exc:
            _LOG.warning("could not read %s to identify submissions: %s", path, exc)
            continue
        for cell in nb.cells:
            meta = cell.get("metadata", {}).get("nbgrader", {})
            if cell.get("cell_type") != "code":
                continue
            marks.update(m for m in (cell.get("id"), meta.get("grade_id")) if isinstance(m, str))
            if isinstance(meta.get("grade_id"), str):
                if meta.get("solution"):
                    answers.append(meta["grade_id"])
                elif meta.get("grade"):
                    tests.append(meta["grade_id"])
        if path == stamps[0][0]:
            released = released_notebook(Path(path))
            if released is not None:
                template = [_text(c.source).strip() for c in released.cells
                            if c.get("cell_type") == "code" and _text(c.source).strip()]
                stubs = [(c.metadata.nbgrader.grade_id, _text(c.source).strip())
                         for c in released.cells if c.get("cell_type") == "code"
                         and c.get("metadata", {}).get("nbgrader", {}).get("solution")]
    return Fingerprint(name=name, files=tuple(Path(p).name for p, _ in stamps),
                       marks=frozenset(marks), answers=tuple(answers), tests=tuple(tests),
                       stubs=tuple(stubs), template=tuple(template))


def released_answers(path: Path) -> dict[str, str]:
    """grade_id -> the released text (stripped) of each answer cell a person grades in the
    instructor notebook ``path`` (nbgrader's ``grade`` and ``solution``, markdown or code);
    ``{}`` without nbgrader. Cached while the file is unchanged."""
    return dict(_released_answers(str(path), _mtime(Path(path))))


@functools.lru_cache(maxsize=64)
def _released_answers(path: str, stamp: int) -> tuple[tuple[str, str], ...]:
    released = released_notebook(Path(path))
    if released is None:
        return ()
    found = []
    for cell in released.cells:
        meta = cell.get("metadata", {}).get("nbgrader", {})
        if meta.get("grade") and meta.get("solution") and isinstance(meta.get("grade_id"), str):
            found.append((meta["grade_id"], _text(cell.source).strip()))
    return tuple(found)


def unanswered(student: Path, released: dict[str, str]) -> set[str]:
    """grade_ids of the answer cells ``released`` that the student's notebook holds as
    released (nbgrader gives such an answer 0 and asks no person: "No response")."""
    if not released:
        return set()
    try:
        nb = nbformat.read(str(student), as_version=4)
    except (OSError, ValueError):
        return set()
    found = set()
    for cell in nb.cells:
        grade_id = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")
        if isinstance(grade_id, str) and grade_id in released and \
                _text(cell.get("source", "")).strip() == released[grade_id]:
            found.add(grade_id)
    return found


def _text(source: Any) -> str:
    return "".join(source) if isinstance(source, list) else str(source)


__all__ = ["Fingerprint", "Identity", "fingerprint", "identify", "known_fingerprints",
           "released_answers", "unanswered"]
