"""otter-grader assignments: read, released and graded as otter 7 does.

One otter "assign"-format master notebook (three questions, public and hidden
tests, points as a total, as a list and per case) goes through the real
``otter assign`` and ``otter run`` and through numgrade; the scores per student
must be equal. Also: ``grader.check`` in the sandbox, the release without any
hidden test, and the messages for what cannot be read.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_raw_cell

from autograder.authoring.release import release
from autograder.engine.assignment import load_assignment
from autograder.engine.otter_format import (
    case_points, checker_tests, otter_cell_tests, read_otter, runnable_source)
from autograder.errors import AssignmentError

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow

#: the code of the hidden cases; none of it may reach a student before grading
HIDDEN = ("x % 2 == 0", "square(-2)", "float(arr.sum())")
SOLUTIONS = ("x = 4", "return n ** 2", "np.linspace(0, 1, 5)")


def _question(name: str, points: object, prompt: str, solution: str,
              tests: list[str]) -> list[nbformat.NotebookNode]:
    return [new_raw_cell(f"# BEGIN QUESTION\nname: {name}\npoints: {points}"),
            new_markdown_cell(prompt),
            new_raw_cell("# BEGIN SOLUTION"), new_code_cell(solution), new_raw_cell("# END SOLUTION"),
            new_raw_cell("# BEGIN TESTS"), *[new_code_cell(t) for t in tests],
            new_raw_cell("# END TESTS"), new_raw_cell("# END QUESTION")]


def master_notebook(*, ok_format: bool = True) -> nbformat.NotebookNode:
    """The master notebook, executed so that its test cells hold their outputs (OK format)."""
    config = "# ASSIGNMENT CONFIG\nname: otterhw\nexport_cell: false\ngenerate: true"
    if not ok_format:
        config += "\ntests:\n  ok_format: false"
    cells = [new_raw_cell(config), new_markdown_cell("# Otter homework"),
             new_code_cell("import numpy as np")]
    cells += _question("q1", 2, "**Question 1.** Set `x` to 4.", "x = 4 # SOLUTION",
                       ["x == 4", "# HIDDEN\nx % 2 == 0"])
    cells += _question("q2", "[1, 2]", "**Question 2.** Write `square(n)`.",
                       "def square(n):\n    # BEGIN SOLUTION\n    return n ** 2\n    # END SOLUTION",
                       ["square(3)", '""" # BEGIN TEST CONFIG\nhidden: true\n""" # END TEST CONFIG\n'
                                     "square(-2)"])
    cells += _question("q3", 3, "**Question 3.** Five points from 0 to 1.",
                       "arr = np.linspace(0, 1, 5) # SOLUTION",
                       ["len(arr)", "print(arr[-1])",
                        '""" # BEGIN TEST CONFIG\nhidden: true\npoints: 1\n""" # END TEST CONFIG\n'
                        "float(arr.sum())"])
    nb = new_notebook(cells=cells, metadata={"kernelspec": {
        "name": "python3", "display_name": "Python 3", "language": "python"}})
    import nbclient

    nbclient.NotebookClient(nb, timeout=120, kernel_name="python3").execute()
    return nb


def write_assignment(root: Path, nb: nbformat.NotebookNode, *, toml: str = "") -> Path:
    folder = root / "otterhw"
    folder.mkdir(parents=True)
    (folder / "assignment.toml").write_text('[assignment]\nname = "otterhw"\n' + toml)
    nbformat.write(nb, folder / "otterhw.ipynb")
    return folder


#: per student, the answers put into otter's own student notebook (answer cells by question)
STUDENTS = {
    "alice": {"q1": "x = 6", "q2": "def square(n):\n    return abs(n) * 3",
              "q3": "arr = np.linspace(0, 1, 4)"},
    "bob": {"q1": "x = 4", "q2": "def square(n):\n    return n * n",
            "q3": "arr = np.linspace(0.0, 1.0, 5)"},
    "carol": {"q1": "x = 4", "q2": "def square(n):\n    return n ** 2",
              "q3": "arr = undefined_name"},
}


def fill(student_nb: nbformat.NotebookNode, answers: dict[str, str]) -> nbformat.NotebookNode:
    """Put ``answers`` into the answer cells (the cell before each ``grader.check``)."""
    nb = nbformat.from_dict(json.loads(json.dumps(student_nb)))
    for i, cell in enumerate(nb.cells):
        for question, code in answers.items():
            if cell.source == f'grader.check("{question}")':
                nb.cells[i - 1].source = code
    return nb


def _run(argv: list[str], cwd: Path, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def _lost_the_port_race(stderr: str) -> bool:
    """True when ``otter run`` failed only because its kernel could not bind its ports.

    jupyter_client picks a kernel's TCP ports by binding to port 0 and letting go; the
    kernel binds them a moment later, and a kernel started at the same time by another
    ``otter run`` may have taken one meanwhile (jupyter/jupyter_client#154,
    nteract/papermill#511). Seen once in CI with the runs below started together: the
    kernel died with ``ZMQError: Address already in use`` before replying to kernel_info.
    """
    return "Address already in use" in stderr and "Kernel died before replying" in stderr


@pytest.fixture(scope="module")
def course(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The master through ``otter assign``, the students through ``otter run`` and numgrade."""
    root = tmp_path_factory.mktemp("otter")
    folder = write_assignment(root, master_notebook())
    assign = _run(["otter", "assign", str(folder / "otterhw.ipynb"), str(root / "dist")], root)
    assert assign.returncode == 0, assign.stderr
    student = nbformat.read(root / "dist" / "student" / "otterhw.ipynb", as_version=4)
    zip_path = next((root / "dist" / "autograder").glob("*.zip"))
    subs = root / "subs"
    subs.mkdir()
    for name, answers in STUDENTS.items():
        nbformat.write(fill(student, answers), subs / f"{name}.ipynb")
        (root / "otter-out" / name).mkdir(parents=True)

    def otter_run(name: str) -> float:
        out = root / "otter-out" / name
        argv = ["otter", "run", "-a", str(zip_path), "-o", str(out), str(subs / f"{name}.ipynb")]
        ran = _run(argv, out)
        if ran.returncode != 0 and _lost_the_port_race(ran.stderr):
            ran = _run(argv, out)  # once: the same run again, on new ports
        assert ran.returncode == 0, ran.stderr
        tests = json.loads((out / "results.json").read_text())["tests"]
        return sum(t.get("score") or 0 for t in tests if t["name"] != "Public Tests")

    # Each ``otter run`` (about 9 s, mostly its own start-up and kernel) and numgrade's
    # batch are independent: run at once, they take the time of the slowest few, not the sum.
    with ThreadPoolExecutor(max_workers=len(STUDENTS) + 1) as pool:
        graded_later = pool.submit(_run, [sys.executable, "-m", "autograder", "grade",
                                          str(folder), str(subs), "--out", str(root / "out")],
                                   REPO)
        runs = {name: pool.submit(otter_run, name) for name in STUDENTS}
        otter_scores = {name: run.result() for name, run in runs.items()}
        graded = graded_later.result()
    assert graded.returncode in (0, 1), graded.stderr
    return {"root": root, "folder": folder, "student": student, "otter": otter_scores,
            "out": root / "out"}


def _result(course: dict[str, object], name: str) -> dict[str, object]:
    return json.loads((Path(str(course["out"])) / name / "results.json").read_text())


def test_scores_equal_otter_run(course: dict[str, object]) -> None:
    otter = course["otter"]
    assert otter == {"alice": 3.0, "bob": 8.0, "carol": 5.0}  # what otter 7 gives them
    for name in STUDENTS:
        result = _result(course, name)
        assert result["max_score"] == pytest.approx(8.0)
        assert result["score"] == pytest.approx(otter[name]), (name, result["tests"])


def test_points_and_hidden_flags_are_otters(course: dict[str, object]) -> None:
    """Per case, the points and hidden flags otter assign wrote for its autograder."""
    from otter.test_files.ok_test import OKTestFile

    graded = nbformat.read(Path(str(course["root"])) / "dist" / "autograder" / "otterhw.ipynb", 4)
    ours = read_otter(Path(str(course["folder"])) / "otterhw.ipynb")
    for question in ours.questions:
        theirs = OKTestFile.from_spec(graded.metadata["otter"]["tests"][question.name])
        assert case_points(question) == tuple(float(c.points) for c in theirs.test_cases)
        assert [c.hidden for c in question.cases] == [c.hidden for c in theirs.test_cases]


def test_grader_check_shows_public_results_in_the_sandbox(course: dict[str, object]) -> None:
    stdout = _result(course, "alice")["extra_data"]["stdout"]
    assert "q2 results: All test cases passed!" in stdout
    assert "q1 - 1 result:" in stdout and "Failed example:" in stdout and "x == 4" in stdout
    assert "q3 - 2 result:" in stdout and "Test case passed" in stdout
    for hidden in HIDDEN:  # the hidden cases are not run by grader.check
        assert hidden not in stdout


def test_release_matches_otter_assign_and_holds_no_hidden_test(course: dict[str, object],
                                                               tmp_path: Path) -> None:
    out = tmp_path / "release"
    notebook = release(load_assignment(Path(str(course["folder"]))), out)
    ours = nbformat.read(notebook, as_version=4)
    theirs = course["student"]
    assert [c.source for c in ours.cells] == [c.source for c in theirs.cells]
    assert ours.metadata["otter"]["tests"] == theirs.metadata["otter"]["tests"]
    for path in out.rglob("*"):
        if path.is_file():
            text = path.read_text(errors="replace")
            for secret in (*HIDDEN, *SOLUTIONS, "BEGIN TESTS", "BEGIN SOLUTION"):
                assert secret not in text, (path, secret)


def test_release_refuses_a_hidden_test_copied_into_public_data(tmp_path: Path) -> None:
    folder = write_assignment(tmp_path, master_notebook(), toml='data = ["notes.txt"]\n')
    (folder / "notes.txt").write_text("Remember: square(-2) is checked too.\n")
    with pytest.raises(AssignmentError, match=r"hidden test: 'square\(-2\)'"):
        release(load_assignment(folder), tmp_path / "release")


def test_grader_check_stand_in_holds_no_hidden_test(tmp_path: Path) -> None:
    """A student cell that walks everything the ``otter`` stand-in holds finds no hidden case.

    (The cell tests themselves, hidden ones included, are sent with the notebook's
    cells and run in the student's process, as in otter: docs/security.md, "Not
    covered".)
    """
    folder = write_assignment(tmp_path, master_notebook())
    nb = fill(nbformat.read(release(load_assignment(folder), tmp_path / "release"), 4),
              STUDENTS["bob"])
    needles = ", ".join(repr(h[:3]) + " + " + repr(h[3:]) for h in HIDDEN)  # not in this source
    nb.cells.append(new_code_cell(
        "import gc, sys\n"
        f"needles = ({needles},)\n"
        "# everything reachable from the otter stand-in (untracked dicts and tuples too)\n"
        "todo, done, seen = [sys.modules['otter']], set(), []\n"
        "while todo:\n"
        "    o = todo.pop()\n"
        "    if id(o) in done:\n"
        "        continue\n"
        "    done.add(id(o))\n"
        "    if isinstance(o, str):\n"
        "        seen += [n for n in needles if n in o and o != n]\n"
        "    elif not isinstance(o, (int, float, bytes, type(None))):\n"
        "        todo.extend(gc.get_referents(o))\n"
        "print('HIDDEN-SEEN' if seen else 'HIDDEN-UNSEEN', 'otter' in sys.modules)"))
    (tmp_path / "subs").mkdir()
    nbformat.write(nb, tmp_path / "subs" / "mallory.ipynb")
    graded = _run([sys.executable, "-m", "autograder", "grade", str(folder),
                   str(tmp_path / "subs"), "--out", str(tmp_path / "out")], REPO)
    assert graded.returncode in (0, 1), graded.stderr
    result = json.loads((tmp_path / "out" / "mallory" / "results.json").read_text())
    assert "HIDDEN-UNSEEN True" in result["extra_data"]["stdout"]
    assert result["score"] == pytest.approx(8.0)  # the hidden cases did run, in grading


def test_checker_is_given_public_cases_only() -> None:
    otter = read_otter_from(master_notebook())
    given = json.dumps(checker_tests(otter))
    assert sorted(checker_tests(otter)["questions"]) == ["q1", "q2", "q3"]
    for hidden in HIDDEN:
        assert hidden not in given
    tests = otter_cell_tests(otter, "otterhw.ipynb")
    assert [(t.name, t.points, t.hidden) for t in tests] == [
        ("q1 - 1", 1.0, False), ("q1 - 2", 1.0, True), ("q2 - 1", 1.0, False),
        ("q2 - 2", 2.0, True), ("q3 - 1", 1.0, False), ("q3 - 2", 1.0, False),
        ("q3 - 3", 1.0, True)]


def read_otter_from(nb: nbformat.NotebookNode, tmp: Path | None = None) -> object:
    import tempfile

    folder = Path(tempfile.mkdtemp()) if tmp is None else tmp
    path = folder / "master.ipynb"
    nbformat.write(nb, path)
    return read_otter(path)


def _run_case(source: str, env: dict[str, object]) -> bool:
    try:
        exec(source, env)
    except AssertionError:
        return False
    return True


def test_exception_format_cases_call_the_function_with_the_globals(tmp_path: Path) -> None:
    nb = new_notebook(cells=[
        new_raw_cell("# ASSIGNMENT CONFIG\ntests:\n  ok_format: false"),
        new_raw_cell("# BEGIN QUESTION\nname: q1\npoints: 4"),
        new_raw_cell("# BEGIN TESTS"),
        new_code_cell("def test_x(x):\n    assert x == 4, 'x must be 4'\ntest_x(x)"),
        new_code_cell('""" # BEGIN TEST CONFIG\nhidden: true\npoints: 3\n""" # END TEST CONFIG\n'
                      "def test_env(env):\n    assert env['x'] > 0"),
        new_raw_cell("# END TESTS"), new_raw_cell("# END QUESTION")])
    otter = read_otter_from(nb, tmp_path)
    assert case_points(otter.questions[0]) == (1.0, 3.0)
    sources = [runnable_source(otter, "q1", i, c) for i, c in enumerate(otter.questions[0].cases, 1)]
    assert [_run_case(s, {"x": 4}) for s in sources] == [True, True]
    assert [_run_case(s, {"x": -1}) for s in sources] == [False, False]
    env: dict[str, object] = {"x": 4}
    _run_case(sources[0], env)
    assert "test_x" not in env and "_numgrade_otter_call" not in env  # leaves no names behind


def test_all_or_nothing_question_is_one_test(tmp_path: Path) -> None:
    nb = new_notebook(cells=[
        new_raw_cell("# BEGIN QUESTION\nname: q1\npoints: 2\nall_or_nothing: true"),
        new_raw_cell("# BEGIN TESTS"), new_code_cell("assert x > 0"),
        new_code_cell("# hidden\nassert x < 10"), new_raw_cell("# END TESTS"),
        new_raw_cell("# END QUESTION")])
    otter = read_otter_from(nb, tmp_path)
    (test,) = otter_cell_tests(otter, "master.ipynb")
    assert (test.name, test.points, test.hidden) == ("q1", 2.0, True)
    assert _run_case(test.source, {"x": 5}) and not _run_case(test.source, {"x": 50})


@pytest.mark.parametrize(("cells", "message"), [
    ([new_raw_cell("# BEGIN QUESTION\nname: q1")], r"not closed; add a raw cell '# END QUESTION'"),
    ([new_raw_cell("# BEGIN QUESTION\npoints: 1"), new_raw_cell("# END QUESTION")],
     r"cell 1: the question has no 'name'"),
    ([new_raw_cell("# BEGIN QUESTION\nname: q1\npoints: [1, 2]"), new_raw_cell("# BEGIN TESTS"),
      new_code_cell("assert True"), new_raw_cell("# END TESTS"), new_raw_cell("# END QUESTION")],
     r"'points' is a list of 2 but the question has 1 test cells"),
    ([new_raw_cell("# BEGIN QUESTION\nname: q1"), new_raw_cell("# BEGIN TESTS"),
      new_code_cell("x == 4"), new_raw_cell("# END TESTS"), new_raw_cell("# END QUESTION")],
     r"cell 3 \(a test of question 'q1'\) has no saved output.*run the master notebook"),
    ([new_raw_cell("# BEGIN QUESTION\nname: q1\npoint: 2"), new_raw_cell("# END QUESTION")],
     r"unknown question key\(s\) 'point'"),
    ([new_raw_cell("# BEGIN SOLUTION")], r"outside a question"),
    ([new_raw_cell("# BEGIN QUESTION\nname: q1"), new_raw_cell("# BEGIN TESTS"),
      new_code_cell("def broken(:\n    pass"), new_raw_cell("# END TESTS"),
      new_raw_cell("# END QUESTION")], r"cell 3: the test cell is not valid Python"),
])
def test_what_cannot_be_read_is_named(tmp_path: Path, cells: list[object], message: str) -> None:
    folder = write_assignment(tmp_path, new_notebook(cells=cells))
    with pytest.raises(AssignmentError, match=message):
        load_assignment(folder)


def test_requirements_txt_fills_assignment_requirements(tmp_path: Path) -> None:
    nb = new_notebook(cells=[
        new_raw_cell("# BEGIN QUESTION\nname: q1"), new_raw_cell("# BEGIN TESTS"),
        new_code_cell("assert True"), new_raw_cell("# END TESTS"), new_raw_cell("# END QUESTION")])
    folder = write_assignment(tmp_path, nb, toml='requirements = ["scipy>=1.11"]\n')
    (folder / "requirements.txt").write_text("# the course's packages\npandas>=2\n\n"
                                             "otter-grader==7.0.0\n")
    assignment = load_assignment(folder)
    assert assignment.requirements == ("scipy>=1.11", "pandas>=2")  # otter's own is not needed
    assert [t.name for t in assignment.cell_tests] == ["q1 - 1"]


def test_the_gradescope_zip_of_an_otter_assignment_scores_as_otter_run(
        course: dict[str, object], tmp_path: Path) -> None:
    """The zip carries the master without its solutions and with every test, hidden ones
    included: each student scores in Gradescope's run as ``otter run`` scored them."""
    import shutil
    import zipfile

    from autograder.authoring.gradescope import gradescope_zip, run_submission
    from autograder.engine.assignment import load_assignment

    assignment = load_assignment(Path(str(course["folder"])))
    archive = gradescope_zip(assignment, tmp_path / "zip")
    with zipfile.ZipFile(archive) as bundle:
        master = bundle.read(f"assignment/{assignment.name}/otterhw.ipynb").decode()
        for answer in ("x = 4", "return n ** 2", "np.linspace(0, 1, 5)"):
            assert answer not in master  # the solutions' code (their markers stay)
        assert "square(-2)" in master and "float(arr.sum())" in master  # hidden tests
        got = {}
        for name in STUDENTS:
            root = tmp_path / name
            bundle.extractall(root / "source")
            (root / "submission").mkdir()
            (root / "results").mkdir()
            shutil.copy(Path(str(course["root"])) / "subs" / f"{name}.ipynb",
                        root / "submission" / "otterhw.ipynb")
            got[name] = run_submission(root).score
    assert got == pytest.approx(course["otter"])
