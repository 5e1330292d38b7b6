"""nbgrader courses as they are: test cells, hidden tests, locked cells, several notebooks.

The engine part first (cell tests placed in the student's notebook and scored on
the trusted side), on assignments written here; the nbgrader course part, graded
by numgrade and by the real ``nbgrader autograde`` side by side, further down.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import nbformat
import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.celltests import CellTest
from autograder.engine.grader import Grader
from tests.support.assignments import CHECK, write_double


def _meta(grade_id: str, *, grade: bool, solution: bool, locked: bool,
          points: float | None = None) -> dict:
    meta = {"grade_id": grade_id, "grade": grade, "solution": solution, "locked": locked,
            "schema_version": 3}
    if points is not None:
        meta["points"] = points
    return {"nbgrader": meta}


def _student(path: Path, cells: list[tuple[str, str | None]]) -> Path:
    """A notebook of code cells ``(source, grade_id)``; a test cell's grade_id marks it locked."""
    book = nbformat.v4.new_notebook()
    for source, grade_id in cells:
        meta = _meta(grade_id, grade=grade_id.startswith("test"), solution=not grade_id.startswith("test"),
                     locked=grade_id.startswith("test")) if grade_id else {}
        book.cells.append(nbformat.v4.new_code_cell(source, metadata=meta))
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(book, path)
    return path


SECRET = "assert double(1000) == 2000  # SECRET-HIDDEN-LINE"


def _double_with_cell_tests(tmp_path: Path):
    folder = write_double(tmp_path, "dbl", {"test_double.py": CHECK})
    tests = (CellTest("test_visible", "dbl.ipynb", 2.0,
                      "assert double(2) == 4, 'double(2) should be 4'\n", grade_id="test_visible"),
             CellTest("test_hidden", "dbl.ipynb", 3.0,
                      "print('LEAKED-HIDDEN-OUTPUT')\n" + SECRET + "\n", hidden=True,
                      grade_id="test_hidden"))
    return replace(load_assignment(folder), cell_tests=tests)


@pytest.mark.parametrize("body, expected", [
    ("def double(x):\n    return 2 * x\n", {"test_visible": 2.0, "test_hidden": 3.0}),
    ("def double(x):\n    return 4 if x == 2 else 0\n", {"test_visible": 2.0, "test_hidden": 0.0}),
    ("def double(x):\n    return x\n", {"test_visible": 0.0, "test_hidden": 0.0}),
])
def test_cell_tests_run_in_place_and_score_as_nbgrader(tmp_path: Path, body: str,
                                                       expected: dict[str, float]) -> None:
    assignment = _double_with_cell_tests(tmp_path)
    path = _student(tmp_path / "sub" / "s.ipynb", [
        (body, "double"), ("assert double(2) == 4", "test_visible"),
        ("# the released hidden cell is blank of tests\n", "test_hidden")])
    with Grader(assignment) as grader:
        result = grader.grade(path, id="s", out_dir=tmp_path / "out" / "s")
    scores = {t.name: t.score for t in result.tests if t.name in expected}
    assert scores == expected
    assert result.max_score == 1 + 2 + 3  # the pytest check and both cell tests count
    hidden = next(t for t in result.tests if t.name == "test_hidden")
    assert hidden.hidden and hidden.output in ("Hidden test passed.", "Hidden test failed.")
    page = (tmp_path / "out" / "s" / "feedback.html").read_text()
    stored = (tmp_path / "out" / "s" / "results.json").read_text()
    for text in (page, stored, result.output, result.stdout):
        assert "SECRET-HIDDEN-LINE" not in text and "LEAKED-HIDDEN-OUTPUT" not in text
        assert "double(1000)" not in text
    if expected["test_visible"] == 0:
        visible = next(t for t in result.tests if t.name == "test_visible")
        assert "double(2) should be 4" in visible.output
    assert not result.cell_errors  # test cells are checks, not the student's cell errors


def test_a_test_cell_that_writes_to_stderr_or_returns_a_number(tmp_path: Path) -> None:
    folder = write_double(tmp_path, "dbl", {"test_double.py": CHECK})
    tests = (CellTest("test_stderr", "dbl.ipynb", 1.0,
                      "import sys\nsys.stderr.write('careful')\n", grade_id="test_stderr"),
             CellTest("test_partial", "dbl.ipynb", 2.0, "x = 0.5\nx\n", grade_id="test_partial"),
             CellTest("test_other", "dbl.ipynb", 1.0, "'a string'\n", grade_id="test_other"))
    assignment = replace(load_assignment(folder), cell_tests=tests)
    path = _student(tmp_path / "s.ipynb", [("def double(x):\n    return 2 * x\n", "double"),
                                           ("", "test_stderr"), ("pass", "test_partial"),
                                           ("pass", "test_other")])
    with Grader(assignment) as grader:
        result = grader.grade(path, id="s")
    scores = {t.name: t.score for t in result.tests}
    assert scores == {"test_stderr": 0.0, "test_partial": 0.5, "test_other": 1.0,
                      "double": 1.0}
