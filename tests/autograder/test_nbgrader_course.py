"""nbgrader courses as they are: test cells, hidden tests, locked cells, several notebooks.

The engine part first (cell tests placed in the student's notebook and scored on
the trusted side), on assignments written here; the nbgrader course part, graded
by numgrade and by the real ``nbgrader autograde`` side by side, further down.
"""

from __future__ import annotations

import copy
import json
import os
import shutil
import subprocess
import sys
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


# -- an nbgrader course, graded by numgrade and by nbgrader ------------------------

#: a 1x1 PNG: the course's picture, which the released folder and the worker must hold
PNG = bytes.fromhex("89504e470d0a1a0a0000000d4948445200000001000000010806000000"
                    "1f15c4890000000d49444154789c6360000002000001e221bc330000000049454e44ae426082")
TEST_CELLS = {"correct_squares", "squares_invalid_input", "test_size"}
HIDDEN_MARK = "HIDDEN-TEST-MARK"


def _cell(kind: str, source: str, **meta) -> nbformat.NotebookNode:
    nbmeta = {"schema_version": 3, "grade": False, "solution": False, "locked": False,
              "task": False, **meta}
    make = nbformat.v4.new_code_cell if kind == "code" else nbformat.v4.new_markdown_cell
    return make(source, metadata={"nbgrader": nbmeta})


def _source_notebooks() -> dict[str, nbformat.NotebookNode]:
    one = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_markdown_cell("Write `squares(n)`: the squares of 1 to n."),
        _cell("code", "def squares(n):\n    ### BEGIN SOLUTION\n"
                      "    if n < 1:\n        raise ValueError('n must be at least 1')\n"
                      "    return [i * i for i in range(1, n + 1)]\n    ### END SOLUTION\n",
              grade_id="squares", solution=True),
        _cell("code", "assert squares(1) == [1]\nassert squares(2) == [1, 4]\n"
                      "### BEGIN HIDDEN TESTS\n"
                      f"assert squares(10) == [i * i for i in range(1, 11)]  # {HIDDEN_MARK}\n"
                      "### END HIDDEN TESTS\n",
              grade_id="correct_squares", grade=True, locked=True, points=2),
        _cell("code", "try:\n    squares(0)\nexcept ValueError:\n    pass\nelse:\n"
                      "    raise AssertionError('squares(0) should raise ValueError')\n",
              grade_id="squares_invalid_input", grade=True, locked=True, points=1),
        _cell("markdown", "YOUR ANSWER HERE", grade_id="explain", grade=True, solution=True,
              points=2),
    ])
    two = nbformat.v4.new_notebook(cells=[
        _cell("code", "from pathlib import Path\nIMAGE = Path('jupyter.png')\n",
              grade_id="setup", locked=True),
        _cell("code", "def image_bytes():\n    ### BEGIN SOLUTION\n"
                      "    return len(IMAGE.read_bytes())\n    ### END SOLUTION\n",
              grade_id="size", solution=True),
        _cell("code", "assert image_bytes() > 0\n### BEGIN HIDDEN TESTS\n"
                      f"assert image_bytes() == {len(PNG)}  # {HIDDEN_MARK}\n### END HIDDEN TESTS\n",
              grade_id="test_size", grade=True, locked=True, points=3),
        _cell("markdown", "Describe the picture (a task).", grade_id="describe", task=True, locked=True,
              points=1),
    ])
    for book in (one, two):
        book.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3",
                                       "language": "python"}
    return {"problem1.ipynb": one, "problem2.ipynb": two}


#: what each student writes in the solution cells, by grade_id
STUDENTS = {
    "alice": {"squares": "def squares(n):\n    if n < 1:\n        raise ValueError('no')\n"
                         "    return [i * i for i in range(1, n + 1)]\n",
              "size": "def image_bytes():\n    return len(IMAGE.read_bytes())\n",
              "explain": "The squares grow like $n^2$."},
    "bob": {"squares": "def squares(n):\n    return [i * i for i in range(1, min(n, 4) + 1)]\n",
            "size": "def image_bytes():\n    return len(IMAGE.read_bytes())\n"},
    "carol": {"squares": "def squares(n):\n    return undefined_name\n",
              "size": "def image_bytes():\n    return 1 / 0\n"},
}


def _nbgrader(course: Path, *args: str) -> None:
    done = subprocess.run([sys.executable, "-m", "nbgrader", *args, "--force"], cwd=course,
                          capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]


@pytest.fixture(scope="module")
def course(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An nbgrader course root: source/ps1 (two notebooks and a picture), the release, and
    three students' submissions in submitted/<student>/ps1/, autograded by nbgrader."""
    root = tmp_path_factory.mktemp("course")
    (root / "nbgrader_config.py").write_text(
        "c = get_config()\nc.CourseDirectory.root = r'%s'\n"
        "c.CourseDirectory.course_id = 'numerics'\n" % root)
    source = root / "source" / "ps1"
    source.mkdir(parents=True)
    for name, book in _source_notebooks().items():
        nbformat.write(book, source / name)
    (source / "jupyter.png").write_bytes(PNG)
    _nbgrader(root, "generate_assignment", "ps1")
    for student, answers in STUDENTS.items():
        folder = root / "submitted" / student / "ps1"
        folder.mkdir(parents=True)
        for name in ("problem1.ipynb", "problem2.ipynb"):
            book = nbformat.read(root / "release" / "ps1" / name, as_version=4)
            for cell in book.cells:
                grade_id = cell.metadata.get("nbgrader", {}).get("grade_id")
                if grade_id in answers:
                    cell.source = answers[grade_id]
            nbformat.write(book, folder / name)
        (folder / "jupyter.png").write_bytes(PNG)
        (folder / "timestamp.txt").write_text("2026-12-01 10:00:00.000000 UTC")
    _nbgrader(root, "autograde", "ps1")
    return root


def _nbgrader_scores(course: Path) -> dict[str, float]:
    from nbgrader.api import Gradebook

    scores = {}
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gradebook:
        for student in STUDENTS:
            submission = gradebook.find_submission("ps1", student)
            scores[student] = sum(grade.auto_score or 0.0 for nb in submission.notebooks
                                  for grade in nb.grades if grade.name in TEST_CELLS)
    return scores


def _nbgrader_unanswered(course: Path) -> dict[str, bool]:
    """Whether nbgrader scored each student's written answer 0 without asking a person."""
    from nbgrader.api import Gradebook

    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gradebook:
        grades = {s: gradebook.find_grade("explain", "problem1", "ps1", s) for s in STUDENTS}
        return {s: g.auto_score == 0 and not g.needs_manual_grade for s, g in grades.items()}


def test_numgrade_scores_an_nbgrader_course_as_nbgrader_does(course: Path, tmp_path: Path) -> None:
    assignment = load_assignment(course / "source" / "ps1")
    assert [p.name for p in assignment.notebooks] == ["problem1.ipynb", "problem2.ipynb"]
    assert {t.name: t.points for t in assignment.cell_tests} == {
        "correct_squares": 2, "squares_invalid_input": 1, "test_size": 3}
    assert {m.name: m.points for m in assignment.manual_cells} == {"explain": 2, "describe": 1}
    expected = _nbgrader_scores(course)
    assert expected == {"alice": 6.0, "bob": 3.0, "carol": 0.0}  # the course works as meant
    assert _nbgrader_unanswered(course) == {"alice": False, "bob": True, "carol": True}
    got = {}
    with Grader(assignment) as grader:
        for student in STUDENTS:
            result = grader.grade(course / "submitted" / student / "ps1", id=student,
                                  out_dir=tmp_path / student)
            got[student] = sum(t.score for t in result.tests if t.kind != "needs-person")
            assert result.max_score == 6 + 3  # autograded points plus the person's
            assert {t.notebook for t in result.tests} == {"problem1.ipynb", "problem2.ipynb"}
            page = (tmp_path / student / "feedback.html").read_text()
            assert HIDDEN_MARK not in page and "squares(10)" not in page
            assert HIDDEN_MARK not in (tmp_path / student / "results.json").read_text()
            assert "problem2.ipynb" in page and "waits for a person" in page
            # bob and carol left the written answer as released: 0 and no person, as
            # nbgrader gives it ("No response"); alice's answer waits for a person
            explain = next(t for t in result.tests if t.name == "explain")
            answered = not _nbgrader_unanswered(course)[student]
            assert explain.kind == ("needs-person" if answered else "missing")
            assert explain.score == 0.0
            assert f"{3 if answered else 1} point(s) wait for a person" in result.output
    assert got == expected


# -- attacks on locked cells ---------------------------------------------------------

def _limit_assignment(root: Path):
    """An nbgrader source folder: locked ``LIMIT = 10``, ``total()``, a test against LIMIT."""
    folder = root / "source" / "sums"
    folder.mkdir(parents=True)
    book = nbformat.v4.new_notebook(cells=[
        _cell("code", "LIMIT = 10\n", grade_id="setup", locked=True),
        _cell("code", "def total():\n    ### BEGIN SOLUTION\n    return sum(range(LIMIT))\n"
                      "    ### END SOLUTION\n", grade_id="answer", solution=True),
        _cell("code", "assert total() == 45, 'total() should be 45'\n", grade_id="test_total",
              grade=True, locked=True, points=2),
    ])
    nbformat.write(book, folder / "sums.ipynb")
    return folder, book


def test_a_duplicated_locked_cell_does_not_hide_the_edited_one(tmp_path: Path) -> None:
    """The edited locked cell loses its nbgrader metadata (keeping its cell id) and an
    untouched copy under the same grade_id sits above it: grade_id alone would restore
    the copy and run the edited cell, and the wrong answer would pass unflagged."""
    folder, book = _limit_assignment(tmp_path)
    setup, answer, test = (copy.deepcopy(c) for c in book.cells)
    answer.source = "def total():\n    return 3\n"  # right only when LIMIT is 3
    edited = copy.deepcopy(setup)
    edited.source = "LIMIT = 3\n"
    edited.metadata = {}  # the id stays: Jupyter's metadata editor does not change it
    untouched = copy.deepcopy(setup)
    untouched["id"] = "copy-of-setup"
    attack = nbformat.v4.new_notebook(cells=[untouched, edited, answer, test])
    path = tmp_path / "mallory.ipynb"
    nbformat.write(attack, path)
    with Grader(load_assignment(folder)) as grader:
        result = grader.grade(path, id="mallory")
    scores = {t.name: t.score for t in result.tests}
    assert scores == {"test_total": 0.0}
    assert any("more than one copy" in note and "`setup`" in note for note in result.notes)


def test_the_student_cell_at_a_test_cells_place_is_the_one_replaced(tmp_path: Path) -> None:
    """A copy of the test cell moved above the answer must not decide where the test runs."""
    folder, book = _limit_assignment(tmp_path)
    setup, answer, test = (copy.deepcopy(c) for c in book.cells)
    answer.source = "def total():\n    return sum(range(LIMIT))\n"
    early = copy.deepcopy(test)
    early["id"] = "moved-copy"
    path = tmp_path / "s.ipynb"
    nbformat.write(nbformat.v4.new_notebook(cells=[setup, early, answer, test]), path)
    with Grader(load_assignment(folder)) as grader:
        result = grader.grade(path, id="s")
    # run at the copy's place (before total() exists) the test would fail
    assert {t.name: t.score for t in result.tests} == {"test_total": 2.0}


# -- the command line on the course --------------------------------------------------

def test_grade_and_release_an_nbgrader_course_from_the_command_line(course: Path,
                                                                    tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    released = subprocess.run(
        [sys.executable, "-m", "autograder", "release", "ps1", "--course", str(course),
         "--out", str(tmp_path / "release")], capture_output=True, text=True, env=env,
        timeout=600)
    assert released.returncode == 0, released.stderr
    assert sorted(p.name for p in (tmp_path / "release").iterdir()) == [
        "assignment.toml", "jupyter.png", "problem1.ipynb", "problem2.ipynb"]
    assert (tmp_path / "release" / "jupyter.png").read_bytes() == PNG
    for name in ("problem1.ipynb", "problem2.ipynb"):
        text = (tmp_path / "release" / name).read_text()
        assert HIDDEN_MARK not in text and "BEGIN SOLUTION" not in text
    # a student checks problem2 in the released folder: both notebooks, each its own tests
    from autograder import api

    for name in ("problem1.ipynb", "problem2.ipynb"):
        shutil.copy(course / "submitted" / "bob" / "ps1" / name, tmp_path / "release" / name)
    checked = api.check(tmp_path / "release" / "problem2.ipynb")
    by_name = {t.name: (t.notebook, t.score) for t in checked.tests if t.kind != "needs-person"}
    assert by_name["test_size"] == ("problem2.ipynb", 3.0)  # its public part passes
    assert by_name["correct_squares"][0] == "problem1.ipynb"
    graded = subprocess.run(
        [sys.executable, "-m", "autograder", "grade", str(course / "source" / "ps1"),
         str(course / "submitted"), "--out", str(tmp_path / "results"), "--no-progress"],
        capture_output=True, text=True, env=env, timeout=900)
    assert graded.returncode in (0, 1), graded.stderr
    folders = sorted(p.name for p in (tmp_path / "results").iterdir() if p.is_dir())
    assert folders == ["alice", "bob", "carol"]  # one result per student, not per notebook
    expected = _nbgrader_scores(course)
    for student in STUDENTS:
        data = json.loads((tmp_path / "results" / student / "results.json").read_text())
        auto = sum(t["score"] for t in data["tests"] if t["extra_data"]["kind"] != "needs-person")
        assert auto == expected[student]
        assert data["max_score"] == 9


def test_an_assignment_toml_adds_pytest_checks_to_the_cell_tests(course: Path,
                                                                 tmp_path: Path) -> None:
    folder = tmp_path / "ps1"
    shutil.copytree(course / "source" / "ps1", folder)
    (folder / "assignment.toml").write_text(
        '[assignment]\nformat = "nbgrader"\nnotebook = "problem2.ipynb"\n')
    (folder / "checks" / "hidden").mkdir(parents=True)
    (folder / "checks" / "hidden" / "test_size.py").write_text(
        f"def test_image_bytes(student):\n    assert student.image_bytes() == {len(PNG)}\n")
    assignment = load_assignment(folder)
    assert [p.name for p in assignment.notebooks] == ["problem2.ipynb", "problem1.ipynb"]
    with Grader(assignment) as grader:
        result = grader.grade(course / "submitted" / "alice" / "ps1", id="alice")
    scores = {(t.notebook, t.name): t.score for t in result.tests if t.kind != "needs-person"}
    assert scores == {("problem2.ipynb", "test_size"): 3.0, ("problem2.ipynb", "image_bytes"): 1.0,
                      ("problem1.ipynb", "correct_squares"): 2.0,
                      ("problem1.ipynb", "squares_invalid_input"): 1.0}


def test_folders_that_are_not_assignments_are_named(course: Path, tmp_path: Path) -> None:
    from autograder.errors import AssignmentError

    with pytest.raises(AssignmentError, match="nbgrader course root; name one of its"):
        load_assignment(course)
    assert load_assignment("ps1", search_root=course).root == (course / "source" / "ps1").resolve()
    (tmp_path / "plain").mkdir()
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("x = 1")]),
                   tmp_path / "plain" / "a.ipynb")
    with pytest.raises(AssignmentError, match="no assignment.toml and no nbgrader notebook"):
        load_assignment(tmp_path / "plain")


def test_the_gradescope_zip_of_an_nbgrader_course_scores_as_nbgrader(course: Path,
                                                                     tmp_path: Path) -> None:
    """Both notebooks bundled without solutions but with their hidden tests; each student's
    folder graded by the zip's run as nbgrader graded it."""
    import zipfile

    from autograder.authoring.gradescope import gradescope_zip, run_submission

    assignment = load_assignment(course / "source" / "ps1")
    archive = gradescope_zip(assignment, tmp_path / "zip")
    with zipfile.ZipFile(archive) as bundle:
        books = {n: bundle.read(n).decode() for n in bundle.namelist() if n.endswith(".ipynb")}
        assert set(books) == {"assignment/ps1/problem1.ipynb", "assignment/ps1/problem2.ipynb"}
        for text in books.values():
            assert "BEGIN SOLUTION" not in text and "raise ValueError('n must" not in text
            assert "len(IMAGE.read_bytes())" not in text
        assert sum(HIDDEN_MARK in text for text in books.values()) == 2  # the grader needs them
        expected = _nbgrader_scores(course)
        got = {}
        for student in STUDENTS:
            root = tmp_path / "gradescope" / student
            bundle.extractall(root / "source")
            shutil.copytree(course / "submitted" / student / "ps1", root / "submission")
            (root / "results").mkdir()
            result = run_submission(root)
            got[student] = sum(t.score for t in result.tests if t.kind != "needs-person")
            assert {t.notebook for t in result.tests} == {"problem1.ipynb", "problem2.ipynb"}
            data = json.loads((root / "results" / "results.json").read_text())
            assert HIDDEN_MARK not in json.dumps(data)
    assert got == expected
