"""The student version of an assignment, made with nbgrader's own preprocessors.

:func:`release` writes into ``out_dir``::

    <notebook>.ipynb        the student template of each notebook, under its own name
                            (no solutions, no hidden tests)
    data/...                the public data files (for an nbgrader folder: every file
                            beside the notebooks), at their paths relative to the folder
    checks/public/...       every file under checks/public/ (tests and their helpers)
    assignment.toml         name, title, notebook, data and rules, so that the
                            released folder can be loaded to run the public checks

Nothing from ``checks/hidden/``, nor ``checks/conftest.py``, is released. After
writing, the output is checked again (defence in depth): a solution or hidden
test marker, or a line from a hidden check, in the written notebook, or a
copy of a hidden check anywhere in ``out_dir``, deletes the notebook and raises
:class:`~autograder.errors.AssignmentError`.
"""

from __future__ import annotations

import copy
import hashlib
import json
import logging
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any

import nbformat

from autograder.authoring.otter_release import otter_template, verify_no_hidden_tests
from autograder.engine.assignment import Assignment
from autograder.engine.otter_format import is_otter_notebook
from autograder.engine.variants import parameters_source, read_roster
from autograder.errors import AssignmentError, UsageError

__all__ = ["release", "student_template", "PREPROCESSORS", "FORBIDDEN_MARKERS"]

#: The passes of ``nbgrader generate_assignment`` that need no course or database
#: (classes of ``nbgrader.preprocessors``), in nbgrader's order
#: (``converters/generate_assignment.py``). Checksums are computed again after
#: the hidden tests are cleared, as nbgrader does. Left out: IncludeHeaderFooter
#: and InstantiateTests (need course configuration), SaveCells (needs the
#: gradebook database).
PREPROCESSORS = (
    "LockCells",
    "ClearSolutions",
    "ClearOutput",
    "CheckCellMetadata",
    "ComputeChecksums",
    "ClearHiddenTests",
    "ClearMarkScheme",
    "ComputeChecksums",
    "CheckCellMetadata",
)
#: Text that must never appear in a released notebook.
FORBIDDEN_MARKERS = ("BEGIN SOLUTION", "END SOLUTION", "BEGIN HIDDEN TESTS",
                     "END HIDDEN TESTS", "BEGIN MARK SCHEME", "END MARK SCHEME")
#: Lines of hidden checks at least this long (stripped) must not appear in the notebook.
_DISTINCTIVE = 32
_LOG = logging.getLogger("autograder.authoring.release")


def student_template(assignment: Assignment, notebook: Path | None = None
                     ) -> nbformat.NotebookNode:
    """The student version of ``notebook`` (default: ``assignment.notebook``), in memory.

    Parameters
    ----------
    assignment : Assignment
    notebook : Path, optional
        One of ``assignment.notebooks``.

    Returns
    -------
    nbformat.NotebookNode
        A format-4 notebook with solution regions replaced by nbgrader's stub
        (``raise NotImplementedError()``), hidden tests and mark schemes
        removed, outputs cleared, nbgrader cells locked and checksummed.

    Raises
    ------
    AssignmentError
        The instructor notebook cannot be read, or nbgrader rejects it (for
        example a solution region outside a solution cell).
    """
    if is_otter_notebook(assignment.notebook):  # otter's assign format, not nbgrader's
        return otter_template(assignment)
    # nbgrader is imported here: it is slow to import and only releasing needs it.
    try:
        from nbgrader import preprocessors
        from nbgrader.nbgraderformat import ValidationError as MetadataError
    except ImportError:
        raise UsageError(
            "Releasing an assignment runs nbgrader's preprocessors, and nbgrader is not "
            "installed: install the instructor's extra, python -m pip install "
            "\"numgrade[instructor]\" (or -e \".[instructor]\" in a checkout).") from None

    source = notebook or assignment.notebook
    nb = _read_instructor(source)
    resources: dict[str, Any] = {}
    for name in PREPROCESSORS:
        try:
            nb, resources = getattr(preprocessors, name)(log=_LOG).preprocess(nb, resources)
        except (RuntimeError, ValueError, MetadataError, KeyError) as exc:
            raise AssignmentError(
                f"{source}: nbgrader's {name} failed: {exc}. "
                "Check the cell's nbgrader metadata (Create Assignment toolbar) and its "
                "### BEGIN/END markers.") from None
    _verify_template(assignment, nb, where="the student template")
    return nb


def release(assignment: Assignment, out_dir: Path, *, server: str | None = None) -> Path:
    """Write the student version of ``assignment`` into ``out_dir``.

    Parameters
    ----------
    assignment : Assignment
    out_dir : Path
        Created if missing; must not be inside the assignment folder.
    server : str, optional
        The course's service (``https://...``), written into every released notebook's
        metadata (``numgrade.server``) so that ``submit()`` in the notebook knows where
        to send it.

    Returns
    -------
    Path
        The first notebook written. Every notebook of the assignment is written
        under its own file name, and every data file at its path.

    Raises
    ------
    AssignmentError
        The template cannot be made, ``out_dir`` is inside the assignment, or
        the written output contains a solution or a hidden check.
    """
    out_dir = Path(out_dir).resolve()
    if out_dir == assignment.root or _is_within(out_dir, assignment.root):
        raise AssignmentError(f"Release folder {out_dir} is inside the assignment folder "
                              f"{assignment.root}; choose a folder outside it.")
    if server is not None and not server.startswith(("http://", "https://")):
        raise UsageError(f"--server takes the address of the course's service, such as "
                         f"https://grader.example.edu; got {server!r}.")
    templates = [(out_dir / nb.name, student_template(assignment, nb))
                 for nb in assignment.notebooks]
    for _, nb in templates:
        if server is not None:
            nb.metadata["numgrade"] = {**nb.metadata.get("numgrade", {}), "server": server}
    out_dir.mkdir(parents=True, exist_ok=True)
    for target, nb in templates:
        nbformat.write(nb, str(target), version=4)
    copied = _copy_public_files(assignment, out_dir)
    _write_toml(assignment, out_dir, templates[0][0], copied)
    try:
        for target, _ in templates:
            _verify_release(assignment, out_dir, target)
    except AssignmentError:
        for target, _ in templates:
            target.unlink(missing_ok=True)
        raise
    return templates[0][0]


_STUDENT_FOLDER = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.@+-]*$")


def release_variants(assignment: Assignment, roster: Path, out_dir: Path, *,
                     server: str | None = None) -> list[Path]:
    """Release one copy per student of ``roster``: ``<out>/<student>/<notebook>`` with the
    notebook's parameters cell (tagged ``[variants] cell``) holding the student's variant.

    Returns the notebooks written, in roster order. Raises :class:`AssignmentError`
    when the assignment declares no variants, the course secret is not set, its
    notebook has no parameters cell, or a student id cannot be a folder name.
    """
    spec = assignment.variants
    if spec is None:
        raise AssignmentError(f"{assignment.root}/assignment.toml has no [variants] table; "
                              "declare the parameters before releasing with --variants.")
    if not spec.active():
        raise AssignmentError(f"--variants draws each student's parameters from the course "
                              f"secret, and {spec.secret_env} is not set: set it to a long "
                              "random string, keep it for the whole course, and give the "
                              "grader the same one (without it every student gets the "
                              "instructor's values: release without --variants).")
    students = read_roster(Path(roster))
    bad = [s for s in students if not _STUDENT_FOLDER.match(s) or ".." in s]
    if bad:
        raise AssignmentError(f"{roster}: student id(s) {bad[:5]} cannot be folder names; "
                              "use ids of letters, digits and . _ - @ +.")
    out_dir = Path(out_dir).resolve()
    with tempfile.TemporaryDirectory(prefix="numgrade-release-") as scratch:
        first = release(assignment, Path(scratch) / "release", server=server)
        template = nbformat.read(str(first), as_version=4)
        cells = [c for c in template.cells if spec.cell in c.get("metadata", {}).get("tags", [])]
        if len(cells) != 1:
            raise AssignmentError(
                f"{assignment.notebook}: --variants needs exactly one code cell tagged "
                f"{spec.cell!r} (the parameters cell); found {len(cells)}. Tag the cell that "
                "sets the parameters (View > Cell Toolbar > Tags).")
        written = []
        for student in students:
            folder = out_dir / student
            shutil.copytree(first.parent, folder, dirs_exist_ok=True)
            cells[0].source = parameters_source(spec.draw(assignment.name, student))
            nbformat.write(template, str(folder / first.name), version=4)
            written.append(folder / first.name)
    return written


# -- reading and writing -------------------------------------------------------

def _read_instructor(path: Path) -> nbformat.NotebookNode:
    try:
        return copy.deepcopy(nbformat.read(str(path), as_version=4))
    except Exception as exc:  # nbformat raises many types on a damaged file
        raise AssignmentError(f"The instructor notebook {path} cannot be read: {exc}. "
                              "Open it in Jupyter and save it.") from None


def _is_within(path: Path, folder: Path) -> bool:
    try:
        path.relative_to(folder)
    except ValueError:
        return False
    return True


def _public_files(assignment: Assignment) -> list[Path]:
    """Every file under ``checks/public/`` except caches."""
    folder = assignment.root / "checks" / "public"
    return sorted(p for p in folder.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc")


def _copy_public_files(assignment: Assignment, out_dir: Path) -> list[Path]:
    """Copy data files and public checks, keeping paths relative to the folder."""
    copied = []
    for source in (*assignment.data_files, *_public_files(assignment)):
        relative = source.relative_to(assignment.root)
        destination = out_dir / relative
        destination.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, destination)
        copied.append(relative)
    return copied


def _write_toml(assignment: Assignment, out_dir: Path, notebook: Path,
                copied: list[Path]) -> None:
    """A minimal ``assignment.toml`` describing the released folder."""
    data = [p.as_posix() for p in copied if p.parts[0] != "checks"]
    lines = [
        "# Written by autograder.authoring.release: the student version of this assignment.",
        "[assignment]",
        f"name = {_toml_str(assignment.name)}",
        f"title = {_toml_str(assignment.title)}",
        f"notebook = {_toml_str(notebook.name)}",
        f"data = [{', '.join(_toml_str(d) for d in data)}]",
        *(['format = "nbgrader"'] if _nbgrader_format(assignment) else []),
        "",
        "[rules]",
        f"forbid = [{', '.join(_toml_str(f) for f in assignment.rules.forbid)}]",
        f"reason = {_toml_str(assignment.rules.reason)}",
        # what an allowed library uses inside (matplotlib's own matplotlib.path): without
        # it a student's `autograder check` would call their plotting cell forbidden
        f"internal_use = [{', '.join(_toml_str(f) for f in assignment.rules.internal_use)}]",
        "",
        "[limits]",
        f"notebook_timeout = {assignment.notebook_timeout!r}",
        f"call_timeout = {assignment.call_timeout!r}",
        *(f"{key} = {value!r}" for key, value in assignment.limits),
    ]
    (out_dir / "assignment.toml").write_text("\n".join(lines) + "\n", encoding="utf-8")


def _nbgrader_format(assignment: Assignment) -> bool:
    """Whether the assignment came from an nbgrader source folder (its tests are cells)."""
    return (len(assignment.notebooks) > 1 or bool(assignment.manual_cells)
            or any(t.grade_id is not None for t in assignment.cell_tests))


def _toml_str(text: str) -> str:
    """A TOML basic string (JSON escapes are valid TOML escapes)."""
    return json.dumps(text, ensure_ascii=True)


# -- defence in depth ----------------------------------------------------------

def _hidden_files(assignment: Assignment) -> list[Path]:
    folder = assignment.root / "checks" / "hidden"
    return sorted(p for p in folder.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc")


def _long_lines(paths: list[Path]) -> set[str]:
    """Stripped lines of the ``.py`` files in ``paths`` that are long and not imports."""
    lines: set[str] = set()
    for path in paths:
        if path.suffix != ".py":
            continue
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            line = line.strip()
            if len(line) >= _DISTINCTIVE and not line.startswith(("import ", "from ", "#")):
                lines.add(line)
    return lines


def _distinctive_lines(assignment: Assignment) -> set[str]:
    """Long lines of the hidden checks that no public check also has."""
    return _long_lines(_hidden_files(assignment)) - _long_lines(_public_files(assignment))


def _verify_template(assignment: Assignment, nb: nbformat.NotebookNode, *, where: str) -> None:
    """Raise when ``nb`` still holds a marker or a line of a hidden check."""
    hidden = _distinctive_lines(assignment)
    for number, cell in enumerate(nb.cells, start=1):
        source = cell.get("source", "")
        for marker in FORBIDDEN_MARKERS:
            if marker in source:
                raise _leak(assignment, where, f"cell {number} still contains {marker!r}")
        for line in source.splitlines():
            if line.strip() in hidden:
                raise _leak(assignment, where,
                            f"cell {number} contains a line of a hidden check: {line.strip()!r}")


def _verify_release(assignment: Assignment, out_dir: Path, notebook: Path) -> None:
    """Check the written notebook and every file in ``out_dir`` for hidden material."""
    text = notebook.read_text(encoding="utf-8")
    for marker in FORBIDDEN_MARKERS:
        if marker in text:
            raise _leak(assignment, str(notebook), f"it contains {marker!r}")
    _verify_template(assignment, nbformat.reads(text, as_version=4), where=str(notebook))
    if is_otter_notebook(assignment.notebook):
        verify_no_hidden_tests(assignment, out_dir)
    secret = {_sha256(p): p for p in _hidden_files(assignment) if p.read_bytes().strip()}
    for path in out_dir.rglob("*"):
        if path.is_file() and _sha256(path) in secret:
            raise _leak(assignment, str(path),
                        f"it is a copy of {secret[_sha256(path)].relative_to(assignment.root)}")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _leak(assignment: Assignment, where: str, detail: str) -> AssignmentError:
    return AssignmentError(
        f"Refusing to release {assignment.name!r}: {where}: {detail}. Move solutions inside "
        "### BEGIN SOLUTION / ### END SOLUTION in solution cells, and keep hidden checks "
        "out of the notebook and the public folders.")
