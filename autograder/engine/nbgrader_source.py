"""Read an nbgrader source assignment folder (``source/ps1/``) as it is.

nbgrader keeps an assignment as a folder of instructor notebooks and the files
they use, with no configuration file; what is graded is written in each cell's
``metadata.nbgrader``:

* ``grade`` and not ``solution``, in a code cell: an autograder test, worth
  ``points`` when it runs without an error (``### BEGIN HIDDEN TESTS`` ...
  ``### END HIDDEN TESTS`` regions are released stripped and run at grading);
* ``grade`` and ``solution``, in a markdown or code cell, and ``task`` cells:
  graded by a person, worth ``points``;
* ``locked``: put back as released at grading (see
  :func:`autograder.engine.notebook.restore_locked`).

:func:`nbgrader_parts` turns that into the cell tests, the cells a person grades,
the notebooks and the extra files of an :class:`~autograder.engine.assignment.Assignment`;
:func:`is_nbgrader_folder` says whether a folder without ``assignment.toml`` is one.
An nbgrader course root (``nbgrader_config.py`` beside ``source/``) names its
assignments by folder under ``source/`` (:func:`course_source_dir`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import nbformat

from autograder.engine.celltests import CellTest, ManualCell
from autograder.errors import AssignmentError

__all__ = ["NbgraderParts", "nbgrader_parts", "is_nbgrader_folder", "course_source_dir",
           "HIDDEN_BEGIN"]

HIDDEN_BEGIN = "### BEGIN HIDDEN TESTS"
#: folders of an assignment that are never released or copied to the worker
_SKIP = frozenset({".ipynb_checkpoints", "__pycache__", "checks", "examples", ".git"})


@dataclass(frozen=True)
class NbgraderParts:
    """What an nbgrader source folder holds, in numgrade's terms."""

    notebooks: tuple[Path, ...]
    extra_files: tuple[Path, ...]
    cell_tests: tuple[CellTest, ...]
    manual_cells: tuple[ManualCell, ...]


def course_source_dir(folder: Path) -> Path | None:
    """``folder/source`` when ``folder`` is an nbgrader course root, else None."""
    if (folder / "nbgrader_config.py").is_file() and (folder / "source").is_dir():
        return folder / "source"
    return None


def _notebooks(root: Path) -> list[Path]:
    return sorted(p.resolve() for p in root.glob("*.ipynb") if p.is_file())


def is_nbgrader_folder(root: Path) -> bool:
    """True when a notebook directly in ``root`` has nbgrader cell metadata."""
    for path in _notebooks(root):
        try:
            book = nbformat.read(str(path), as_version=4)
        except Exception:  # an unreadable notebook is reported when it is loaded
            continue
        if any(isinstance(c.get("metadata", {}).get("nbgrader"), dict) for c in book.cells):
            return True
    return False


def nbgrader_parts(root: Path, *, first: str | None = None) -> NbgraderParts:
    """The notebooks (``first`` first, else by name), extra files, tests and manual cells.

    Raises
    ------
    AssignmentError
        No notebook, a notebook that cannot be read, a graded cell without a
        ``grade_id`` or with points that are not a non-negative number, two
        graded cells of one notebook with the same ``grade_id``.
    """
    notebooks = _notebooks(root)
    if not notebooks:
        raise AssignmentError(f"{root} holds no notebook (*.ipynb); an nbgrader source "
                              "folder holds the instructor's notebooks.")
    if first is not None:
        notebooks.sort(key=lambda p: p.name != first)
    tests: list[CellTest] = []
    manual: list[ManualCell] = []
    for path in notebooks:
        found_tests, found_manual = _graded_cells(path)
        tests += found_tests
        manual += found_manual
    return NbgraderParts(notebooks=tuple(notebooks), extra_files=_extra_files(root),
                         cell_tests=tuple(tests), manual_cells=tuple(manual))


def _extra_files(root: Path) -> tuple[Path, ...]:
    """Every file of the folder that is not a notebook or numgrade's own (images, data)."""
    found = []
    for path in sorted(root.rglob("*")):
        relative = path.relative_to(root)
        if any(part in _SKIP for part in relative.parts[:-1]) or relative.parts[0] in _SKIP:
            continue
        if not path.is_file() or path.is_symlink():
            continue
        if len(relative.parts) == 1 and (path.suffix == ".ipynb" or path.name == "assignment.toml"):
            continue
        found.append(path.resolve())
    return tuple(found)


def _graded_cells(path: Path) -> tuple[list[CellTest], list[ManualCell]]:
    try:
        book = nbformat.read(str(path), as_version=4)
    except Exception as exc:  # nbformat raises several kinds for a damaged file
        raise AssignmentError(f"The instructor notebook {path} cannot be read: {exc}. "
                              "Open it in Jupyter and save it again.") from None
    tests: list[CellTest] = []
    manual: list[ManualCell] = []
    seen: set[str] = set()
    for number, cell in enumerate(book.cells, start=1):
        meta = cell.get("metadata", {}).get("nbgrader", {})
        if not isinstance(meta, dict) or not (meta.get("grade") or meta.get("task")):
            continue
        grade_id = _grade_id(path, number, meta, seen)
        points = _points(path, grade_id, meta)
        source = cell.get("source", "")
        if meta.get("grade") and not meta.get("solution") and cell.get("cell_type") == "code":
            tests.append(CellTest(name=grade_id, notebook=path.name, points=points,
                                  source=source, hidden=HIDDEN_BEGIN in source,
                                  grade_id=grade_id))
        else:
            manual.append(ManualCell(name=grade_id, notebook=path.name, points=points,
                                     kind="task" if meta.get("task") else "answer"))
    return tests, manual


def _grade_id(path: Path, number: int, meta: dict[str, Any], seen: set[str]) -> str:
    grade_id = meta.get("grade_id")
    if not isinstance(grade_id, str) or not grade_id.strip():
        raise AssignmentError(f"{path}: graded cell {number} has no grade_id; give it one in "
                              "nbgrader's cell toolbar (View > Cell Toolbar > Create Assignment).")
    if grade_id in seen:
        raise AssignmentError(f"{path}: two graded cells share the grade_id {grade_id!r}; "
                              "give each cell its own.")
    seen.add(grade_id)
    return grade_id


def _points(path: Path, grade_id: str, meta: dict[str, Any]) -> float:
    value = meta.get("points", 0)
    try:
        points = float(value)
    except (TypeError, ValueError):
        points = -1.0
    if points < 0 or points != points:
        raise AssignmentError(f"{path}: cell {grade_id!r} has points {value!r}; points must be "
                              "a number of at least 0.")
    return points
