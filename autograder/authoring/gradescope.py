"""The Gradescope autograder zip, and the run inside Gradescope's image.

``gradescope_zip`` bundles the engine's source, ``reference``, the assignment
(hidden checks included, its examples left out) and two scripts; Gradescope runs
``setup.sh`` once and ``run_autograder`` per submission, which calls
:func:`run_submission`. The zip is staff material: it holds the hidden checks.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import io
import json
import zipfile
from pathlib import Path

import nbformat

import autograder
from autograder.results.feedback import as_students_see
from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.grader import Grader, error_result
from autograder.errors import UsageError
from autograder.results.exports import write_gradescope_result
from autograder.results.model import SubmissionResult

#: where Gradescope puts things; every path below it can be moved with this variable
ROOT_ENV = "AUTOGRADER_ROOT"
GRADESCOPE_ROOT = Path("/autograder")
#: the scripts at the top of the zip, and the package templates they come from
GRADESCOPE_SCRIPTS = {"setup.sh": "gradescope_setup.sh", "run_autograder": "gradescope_run_autograder"}
_SKIP_PARTS = {"__pycache__", ".ipynb_checkpoints", ".pytest_cache", ".mypy_cache", ".hypothesis"}
_EPOCH = (1980, 1, 1, 0, 0, 0)


def source_root() -> Path:
    """The checkout this package runs from (``pyproject.toml``, ``autograder/``, ``reference/``)."""
    root = Path(autograder.__file__).resolve().parent.parent
    missing = [n for n in ("pyproject.toml", "README.md", "autograder", "reference",
                           "reference/pyproject.toml")
               if not (root / n).exists()]
    if missing:
        raise UsageError(f"The Gradescope zip bundles this package's source, but {root} lacks "
                         f"{', '.join(missing)}; run the command from a source checkout "
                         "(pip install -e .).")
    return root


def _files(folder: Path, *, skip_top: tuple[str, ...] = ()) -> list[Path]:
    def wanted(path: Path) -> bool:
        parts = path.relative_to(folder).parts
        return (path.is_file() and path.suffix != ".pyc" and parts[0] not in skip_top
                and not any(q in _SKIP_PARTS or q.endswith(".egg-info") for q in parts))
    return sorted(p for p in folder.rglob("*") if wanted(p))


def gradescope_entries(assignment: Assignment) -> list[tuple[str, Path | bytes, bool]]:
    """What the zip holds: (name in the zip, file or bytes, executable), in zip order.

    The two scripts at the top, then ``pyproject.toml``, ``README.md``,
    ``autograder/`` and ``reference/`` (installed by ``setup.sh``), then the
    assignment under ``assignment/<name>/`` with its hidden checks and without
    its sample submissions (``examples/``).
    """
    root = source_root()
    templates = importlib.resources.files("autograder.authoring") / "templates"
    entries: list[tuple[str, Path | bytes, bool]] = [
        (name, (templates / template).read_bytes(), True)
        for name, template in GRADESCOPE_SCRIPTS.items()]
    entries += [(name, root / name, False) for name in ("pyproject.toml", "README.md")]
    for package in ("autograder", "reference"):
        entries += [(p.relative_to(root).as_posix(), p, False) for p in _files(root / package)]
    # The instructor notebooks hold the solutions: the zip carries each without them.
    bundled = {nb: nbformat.writes(bundled_notebook(assignment, nb)).encode()
               for nb in assignment.notebooks}
    for path in _files(assignment.root, skip_top=("examples",)):
        name = f"assignment/{assignment.name}/{path.relative_to(assignment.root).as_posix()}"
        entries.append((name, bundled.get(path, path), False))
    return entries


def bundled_notebook(assignment: Assignment, notebook: Path) -> nbformat.NotebookNode:
    """The instructor notebook ``notebook`` as the zip carries it: without solutions.

    For numgrade's own format that is the released notebook (the grader needs it
    only to restore locked cells; the checks are files). Where the tests are cells
    (nbgrader's test cells, otter's test blocks) they are kept, hidden ones
    included, so the assignment loads from the zip with every test and its points.
    """
    from autograder.authoring.otter_release import otter_bundle
    from autograder.authoring.release import student_template  # imports nbgrader: instructors only
    from autograder.engine.otter_format import is_otter_notebook

    if is_otter_notebook(notebook):
        return otter_bundle(assignment)
    if not any(t.notebook == notebook.name for t in assignment.cell_tests):
        return student_template(assignment, notebook)
    from nbgrader import preprocessors

    book = nbformat.read(str(notebook), as_version=4)
    resources: dict[str, object] = {}
    for name in ("ClearSolutions", "ClearOutput"):
        book, resources = getattr(preprocessors, name)().preprocess(book, resources)
    return book


def gradescope_zip(assignment: Assignment, out_dir: Path) -> Path:
    """Write ``out_dir/<name>-gradescope.zip``, the autograder zip Gradescope's settings take.

    The zip is reproducible: entries in a fixed order with a fixed date, so
    the same sources give the same bytes.
    """
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, content, executable in gradescope_entries(assignment):
            info = zipfile.ZipInfo(name, date_time=_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = ((0o100755 if executable else 0o100644) << 16)
            data = content if isinstance(content, bytes) else content.read_bytes()
            archive.writestr(info, data)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{assignment.name}-gradescope.zip"
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(buffer.getvalue())
    tmp.replace(path)
    return path


def bundled_assignment(source: Path) -> Path:
    """The one assignment folder in an unpacked zip (``source/assignment/<name>/``)."""
    # one folder: numgrade's own (assignment.toml) or an nbgrader or otter assignment
    found = sorted(p for p in (source / "assignment").glob("*") if p.is_dir())
    if len(found) != 1:
        raise UsageError(f"Expected one assignment under {source / 'assignment'}, found "
                         f"{len(found)}; rebuild the zip with 'autograder gradescope'.")
    return found[0]


def gradescope_student(root: Path) -> str | None:
    """The submitter's id from Gradescope's ``submission_metadata.json`` (seeds unseen data)."""
    try:
        users = json.loads((root / "submission_metadata.json").read_text())["users"]
        first = users[0]
        return str(first.get("sid") or first.get("email") or first.get("name")) or None
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError):
        return None


def pick_notebook(folder: Path, expected_name: str) -> tuple[Path, str]:
    """The notebook to grade among a Gradescope submission's files, and a note for the student.

    The file named like the assignment's notebook wins; else the only notebook;
    else the first by name, with a note saying so. With no notebook at all the
    expected path is returned (the grader then reports it missing).
    """
    # Regular files only: a link could point at any file of the image (the bundled
    # assignment, another notebook); the grader refuses one if it is picked anyway.
    notebooks = sorted(p for p in folder.rglob("*.ipynb")
                       if p.is_file() and not p.is_symlink() and ".ipynb_checkpoints" not in p.parts)
    named = [p for p in notebooks if p.name == expected_name]
    if named:
        return named[0], ""
    if len(notebooks) == 1 or not notebooks:
        return (notebooks[0] if notebooks else folder / expected_name), ""
    names = ", ".join(p.name for p in notebooks)
    return notebooks[0], (f"You submitted several notebooks ({names}) and none is named "
                          f"{expected_name}; {notebooks[0].name} was graded.")


def run_submission(root: Path) -> "SubmissionResult":
    """Grade ``root/submission/`` against the bundled assignment into ``root/results/``."""
    found = load_assignment(bundled_assignment(root / "source"))
    if len(found.notebooks) > 1:  # the grader takes the folder and finds each notebook
        notebook, note = root / "submission", ""
    else:
        notebook, note = pick_notebook(root / "submission", found.notebook.name)
    student = gradescope_student(root) or notebook.stem
    out = root / "results"
    with Grader(found) as grader:
        try:
            result = grader.grade(notebook, id=student, out_dir=out)
        except Exception as exc:  # the grader's own failure: Gradescope still gets a result
            result = error_result(found, notebook, student, exc)
    if note:
        result = dataclasses.replace(result, output=f"{note} {result.output}")
    # Gradescope itself holds back "after_due_date" checks until the due date; the
    # "hidden" and "input" levels are cut here, since Gradescope shows every output it gets.
    write_gradescope_result(out, as_students_see(result, past_deadline=True))
    return result
