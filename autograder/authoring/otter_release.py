"""The student notebook of an otter-grader assignment, as ``otter assign`` writes it.

From the master notebook (see :mod:`autograder.engine.otter_format`):

* the ASSIGNMENT CONFIG and every ``# BEGIN/END ...`` raw cell are dropped;
* solutions are stripped by otter's rules (``otter/assign/solutions.py``): a line
  ending in ``# SOLUTION`` becomes ``...`` (an assignment keeps its left side,
  ``x = ...``), ``# BEGIN SOLUTION`` ... ``# END SOLUTION`` lines become one
  ``...`` (nothing with ``NO PROMPT``), lines ending in ``# SOLUTION NO PROMPT``,
  ``# BEGIN PROMPT``, ``# END PROMPT`` or ``# SEED`` are dropped; a Markdown cell in a
  solution block becomes "_Type your answer here, replacing this text._";
* test cells are dropped; a question with public tests gets a locked
  ``grader.check("q1")`` cell where its tests were, and the notebook an init cell
  (``import otter; grader = otter.Notebook(...)``) unless ``init_cell: false``;
* the public tests, and only they, go into the notebook's metadata (``otter.tests``,
  otter's OK-format dicts or exception-format files) so that ``grader.check`` also
  works in a student's own Jupyter with otter-grader installed;
* outputs are cleared.

otter is not a dependency of the grader (it is large, and releasing needs only these
rules), so they are written out here. :func:`verify_no_hidden_tests` then reads
every file released for a hidden test's code.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import nbformat

from autograder.engine.assignment import Assignment
from autograder.engine.otter_format import (
    BOUNDARY, CONFIG, OtterNotebook, OtterQuestion, case_points, doctest_text, read_otter)
from autograder.errors import AssignmentError

__all__ = ["otter_bundle", "otter_template", "strip_solutions", "verify_no_hidden_tests"]

# otter's solution_assignment_regex, solution_line_regex and begin_solution_regex
_ASSIGNMENT = re.compile(r"(\s*(?:[\w.]+(?=[^\w.])(?:\[['\"]?.*['\"]?\])*(?:,\s*)?)+\s*=).* ?# ?SOLUTION")
_LINE = re.compile(r"(\s*).* ?# ?SOLUTION")
_BEGIN = re.compile(r"(\s*)# BEGIN SOLUTION( NO PROMPT)?")
_SKIP = ("# SOLUTION NO PROMPT", "# BEGIN PROMPT", "# END PROMPT", "# SEED")
_MARKDOWN_ANSWER = "_Type your answer here, replacing this text._"
_LOCKED = {"deletable": False, "editable": False}
#: text that must not be in a released otter notebook
MARKERS = ("# BEGIN SOLUTION", "# END SOLUTION", "BEGIN TESTS", "BEGIN QUESTION",
           "BEGIN TEST CONFIG", "ASSIGNMENT CONFIG")
#: hidden-test lines shorter than this are too common to mean a leak (``x``, ``True``)
_DISTINCTIVE = 6


def strip_solutions(source: str, *, where: str) -> str:
    """otter's ``replace_solutions`` for Python, on one cell's source."""
    kept: list[str] = []
    inside = False
    for line in source.split("\n"):
        if any(line.rstrip().endswith(s) for s in _SKIP):
            continue
        if line.rstrip().endswith("# END SOLUTION"):
            if not inside:
                raise AssignmentError(f"{where}: '# END SOLUTION' without '# BEGIN SOLUTION'.")
            inside = False
            continue
        if inside:
            continue
        begin = _BEGIN.match(line)
        if begin:
            inside = True
            if begin.group(2):
                continue
            line = begin.group(1) + "..."
        match = _ASSIGNMENT.match(line)
        if match:
            line = match.group(1) + " ..."
        elif (match := _LINE.match(line)):
            line = match.group(1) + "..."
        kept.append(line)
    if inside:
        raise AssignmentError(f"{where}: '# BEGIN SOLUTION' without '# END SOLUTION'; add it.")
    return "\n".join(kept)


def _public_metadata(otter: OtterNotebook, question: OtterQuestion) -> Any:
    """otter's test file of ``question`` with its hidden cases left out."""
    points = case_points(question)
    public = [(c, p) for c, p in zip(question.cases, points) if not c.hidden]
    declared = question.points
    if isinstance(declared, list):
        declared = [p for c, p in zip(question.cases, declared) if not c.hidden]
    if otter.ok_format:
        cases = [{"code": doctest_text(c), "hidden": False, "locked": False} for c, _ in public]
        return {"name": question.name, "points": declared,
                "suites": [{"cases": cases, "scored": True, "setup": "", "teardown": "",
                            "type": "doctest"}]}
    # otter's EXCEPTION_BASED_TEST_FILE_TEMPLATE, public cases only
    body = "".join(f"@test_case(points={p!r}, hidden=False)\n{c.source.strip()}\n\n"
                   for c, p in public)
    return (f"from otter.test_files import test_case\n\nOK_FORMAT = False\n\n"
            f"name = {question.name!r}\npoints = {declared!r}\n\n{body}")


def otter_template(assignment: Assignment) -> nbformat.NotebookNode:
    """The student notebook of the otter assignment ``assignment``, in memory."""
    otter = read_otter(assignment.notebook)
    master = nbformat.read(str(assignment.notebook), as_version=4)
    questions = {q.name: q for q in otter.questions}
    cells: list[Any] = []
    if otter.config.get("init_cell", True):
        cells.append(nbformat.v4.new_code_cell(
            f'# Initialize Otter\nimport otter\ngrader = otter.Notebook("{assignment.notebook.name}")',
            metadata=dict(_LOCKED)))
    block, question = None, None
    for number, cell in enumerate(master.cells, start=1):
        first = (str(cell.source).splitlines() or [""])[0]
        if cell.cell_type == "raw" and CONFIG.match(first):
            continue
        boundary = BOUNDARY.match(first) if cell.cell_type == "raw" else None
        if boundary:
            edge, kind = boundary.group(1).lower(), boundary.group(2).lower()
            if kind == "question":
                question = questions.get(_question_name(cell)) if edge == "begin" else None
            elif edge == "end" and kind == "tests" and question is not None:
                if question.check_cell and any(not c.hidden for c in question.cases):
                    cells.append(nbformat.v4.new_code_cell(f'grader.check("{question.name}")',
                                                           metadata=dict(_LOCKED)))
            block = kind if edge == "begin" and kind != "question" else None
            continue
        if block == "tests":
            continue
        cells.append(_student_cell(cell, in_solution=block == "solution",
                                   where=f"{assignment.notebook}: cell {number}"))
    nb = nbformat.v4.new_notebook(cells=cells, metadata=dict(master.metadata))
    nb.metadata["otter"] = {"OK_FORMAT": otter.ok_format, "assignment_name": assignment.name,
                            "tests": {q.name: _public_metadata(otter, q) for q in otter.questions
                                      if not q.manual and any(not c.hidden for c in q.cases)}}
    verify_template(assignment, otter, nbformat.writes(nb))
    return nb


def otter_bundle(assignment: Assignment) -> nbformat.NotebookNode:
    """The master notebook without its solutions, for staff bundles (the Gradescope zip).

    Every question, config and test cell is kept, hidden tests included, so that
    the assignment loads from the bundle with the same tests and points; only
    what is between ``# BEGIN SOLUTION`` and ``# END SOLUTION`` (and ``# SOLUTION``
    lines) is replaced as in the student notebook.
    """
    master = nbformat.read(str(assignment.notebook), as_version=4)
    cells: list[Any] = []
    block = None
    for number, cell in enumerate(master.cells, start=1):
        first = (str(cell.source).splitlines() or [""])[0]
        boundary = BOUNDARY.match(first) if cell.cell_type == "raw" else None
        if boundary:
            edge, kind = boundary.group(1).lower(), boundary.group(2).lower()
            block = kind if edge == "begin" and kind != "question" else None
        if boundary or block == "tests" or (cell.cell_type == "raw" and CONFIG.match(first)):
            cells.append(nbformat.from_dict(dict(cell)))
            continue
        student = _student_cell(cell, in_solution=block == "solution",
                                where=f"{assignment.notebook}: cell {number}")
        if cell.cell_type == "code":
            student.metadata = dict(cell.metadata)  # the same cell, without its answer
        cells.append(student)
    return nbformat.v4.new_notebook(cells=cells, metadata=dict(master.metadata))


def _question_name(cell: Any) -> str:
    for line in str(cell.source).splitlines()[1:]:
        key, _, value = line.partition(":")
        if key.strip() == "name":
            return value.strip().strip("'\"")
    return ""


def _student_cell(cell: Any, *, in_solution: bool, where: str) -> Any:
    if cell.cell_type == "code":
        new = nbformat.v4.new_code_cell(strip_solutions(cell.source, where=where),
                                        metadata=dict(cell.metadata))
        if in_solution:
            new.metadata["tags"] = [*new.metadata.get("tags", []), "otter_answer_cell"]
        return new
    if cell.cell_type == "markdown" and in_solution:
        return nbformat.v4.new_markdown_cell(_MARKDOWN_ANSWER)
    return nbformat.from_dict(dict(cell))


def _hidden_lines(otter: OtterNotebook) -> set[str]:
    """Lines of hidden tests that no public test has."""
    def lines(public: bool) -> set[str]:
        return {line.strip() for q in otter.questions for c in q.cases if c.hidden != public
                for line in c.source.splitlines() if len(line.strip()) >= _DISTINCTIVE
                and not line.strip().startswith("#")}
    return lines(False) - lines(True)


def verify_template(assignment: Assignment, otter: OtterNotebook, text: str) -> None:
    """Raise when the written notebook still holds a marker or a hidden test's line."""
    for marker in MARKERS:
        if marker in text:
            raise _leak(assignment, f"the student notebook still contains {marker!r}")
    for line in _hidden_lines(otter):
        if line in text:
            raise _leak(assignment, f"the student notebook contains a hidden test: {line!r}")


def verify_no_hidden_tests(assignment: Assignment, out_dir: Path) -> None:
    """Read every file under ``out_dir`` for a line of a hidden test (defence in depth)."""
    hidden = _hidden_lines(read_otter(assignment.notebook))
    for path in sorted(out_dir.rglob("*")):
        if not path.is_file():
            continue
        text = path.read_bytes().decode("utf-8", errors="replace")
        for line in hidden:
            if line in text:
                raise _leak(assignment, f"{path} contains a hidden test: {line!r}")


def _leak(assignment: Assignment, detail: str) -> AssignmentError:
    return AssignmentError(
        f"Refusing to release {assignment.name!r}: {detail}. Keep hidden tests inside "
        "'# BEGIN TESTS' / '# END TESTS' with 'hidden: true' in their TEST CONFIG (or a first "
        "line '# HIDDEN'), and solutions inside '# BEGIN SOLUTION' / '# END SOLUTION'.")
