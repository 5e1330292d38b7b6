"""Manually graded cells in numgrade's own format, and what a person's grading does to a result.

Attacks on the grading page's rendering of student text are here too: a
``<script>`` written as markdown, one smuggled through LaTeX, a ``javascript:``
link and a picture that is not one.
"""

from __future__ import annotations

import base64
from pathlib import Path

import nbformat
import pytest

from autograder.engine.assignment import load_assignment
from autograder.errors import AssignmentError
from autograder.results.adjust import ManualMark, ScoreOverride, adjust
from autograder.results.model import CheckResult, SubmissionResult
from autograder.service.answers import read_answer, render_markdown
from tests.support.assignments import CHECK, write_double

MANUAL = '\n[[manual]]\ncell = "explain"\npoints = 3\n'


def with_answer_cell(folder: Path, tag: str = "manual:explain") -> None:
    path = folder / f"{folder.name}.ipynb"
    book = nbformat.read(path, as_version=4)
    book.cells.append(nbformat.v4.new_markdown_cell("Explain.", metadata={"tags": [tag]}))
    nbformat.write(book, path)


def test_a_manual_table_names_a_tagged_cell_and_its_points(tmp_path: Path) -> None:
    folder = write_double(tmp_path, "essay", {"test_double.py": CHECK})
    with_answer_cell(folder)
    (folder / "assignment.toml").write_text((folder / "assignment.toml").read_text() + MANUAL)
    cells = load_assignment(folder).manual_cells
    assert [(c.name, c.notebook, c.points) for c in cells] == [("explain", "essay.ipynb", 3.0)]


@pytest.mark.parametrize("entry, words", [
    ('\n[[manual]]\ncell = "missing"\npoints = 3\n', "tag the answer cell manual:missing"),
    ('\n[[manual]]\ncell = "explain"\npoints = 0\n', "points = a positive number"),
    ('\n[[manual]]\ncell = "explain"\npoints = true\n', "points = a positive number"),
    ('\nmanual = "explain"\n', "[[manual]] table"),
])
def test_a_bad_manual_table_says_what_to_write(tmp_path: Path, entry: str, words: str) -> None:
    folder = write_double(tmp_path, "essay", {"test_double.py": CHECK})
    with_answer_cell(folder)
    toml = folder / "assignment.toml"
    text = toml.read_text()
    toml.write_text(entry + text if not entry.startswith("\n[[") else text + entry)
    with pytest.raises(AssignmentError, match=words.replace("[", r"\[").replace("]", r"\]")):
        load_assignment(folder)


def _result() -> SubmissionResult:
    tests = (CheckResult("auto", 1.0, 1.0, "", False),
             CheckResult("explain", 0.0, 3.0, "waits", False, kind="needs-person"))
    return SubmissionResult("s", "x.ipynb", "essay", "k", "0" * 64, "graded", "", tests, 0.0, 1)


def test_manual_points_are_clamped_to_the_question_and_overrides_add_up() -> None:
    marked = adjust(_result(), {"explain": ManualMark(5.0, (("all", 5.0),), "fine")}, {})
    assert marked.score == 4.0 and marked.tests[1].kind == "ok"  # 5 clamped to 3
    negative = adjust(_result(), {"explain": ManualMark(-2.0, (("wrong", -2.0),), "")}, {})
    assert negative.score == 1.0  # never below 0 for the question
    total = adjust(_result(), {}, {"": ScoreOverride("", 2.5, "late work accepted")})
    assert total.score == 2.5 and "late work accepted" in total.tests[-1].output
    check = adjust(_result(), {}, {"auto": ScoreOverride("auto", 0.0, "copied")})
    assert check.score == 0.0 and "copied" in check.tests[0].output


@pytest.mark.parametrize("attack", [
    "<script>alert(1)</script>",
    "$\\text{<script>alert(2)</script>}$",  # latex2mathml copies \text's content as it is
    "$\\href{javascript:alert(3)}{x}$",  # ... and \href's target as an attribute
    "[y](javascript:alert(4))",
    "<img src=x onerror=alert(5)>",
])
def test_a_script_in_markdown_or_latex_never_reaches_the_staff_page(attack: str) -> None:
    html = str(render_markdown(attack))
    # what is left of it is text: no element, no attribute a browser would act on
    assert "<script" not in html and "<img" not in html and "javascript:" not in html.replace(
        "[y](javascript:", "")
    assert 'href="' not in html or 'href="#' in html


def test_formulas_become_mathml() -> None:
    assert "<mfrac>" in str(render_markdown("$\\frac{a}{b}$ and $$x^2$$"))


def test_only_real_pictures_of_an_answer_are_shown(tmp_path: Path) -> None:
    png = base64.b64encode(b"\x89PNG\r\n\x1a\n" + b"0" * 20).decode()
    fake = base64.b64encode(b"<svg onload=alert(1)>").decode()
    cell = nbformat.v4.new_code_cell("plot()", metadata={"tags": ["manual:plot"]}, outputs=[
        nbformat.v4.new_output("display_data", data={"image/png": png}),
        nbformat.v4.new_output("display_data", data={"image/png": fake})])
    path = tmp_path / "s.ipynb"
    nbformat.write(nbformat.v4.new_notebook(cells=[cell]), path)
    answer = read_answer(path, "plot")
    assert answer.found and answer.pictures == (f"data:image/png;base64,{png}",)
    assert not read_answer(path, "other").found
