"""The student version: nbgrader's passes, public files only, and the leak checks."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output
from nbgrader.utils import compute_checksum

from autograder.authoring.release import release, student_template
from autograder.engine.assignment import Assignment, load_assignment
from autograder.errors import AssignmentError

SOLUTION = "    hull = sorted(points)  # the secret solution line\n"
HIDDEN_LINE = "assert student.convex_hull([[0, 0]]) == [[0, 0]], 'hidden dataset'"
PUBLIC_CHECK = "def test_public(student):\n    assert student.convex_hull([]) == []\n"
HIDDEN_CHECK = f"def test_hidden(student):\n    {HIDDEN_LINE}\n"


def _meta(grade_id: str, *, solution: bool = False, grade: bool = False,
          locked: bool = False, points: float | None = None) -> dict:
    meta = {"grade_id": grade_id, "solution": solution, "grade": grade, "locked": locked,
            "schema_version": 3}
    if points is not None:
        meta["points"] = points
    return {"nbgrader": meta}


def instructor_notebook() -> nbformat.NotebookNode:
    """A tiny nbgrader source notebook: locked text, a solution, a test cell."""
    intro = new_markdown_cell("# Convex hull\nWrite `convex_hull`.",
                              metadata=_meta("intro", locked=True))
    answer = new_code_cell(
        "def convex_hull(points):\n    ### BEGIN SOLUTION\n" + SOLUTION
        + "    return hull\n    ### END SOLUTION\n",
        metadata=_meta("convex-hull", solution=True),
        outputs=[new_output("stream", name="stdout", text="instructor output\n")],
        execution_count=3)
    tests = new_code_cell(
        "assert convex_hull([]) == []\n### BEGIN HIDDEN TESTS\n"
        "assert convex_hull([[1, 1]]) == [[1, 1]]\n### END HIDDEN TESTS\n",
        metadata=_meta("test-hull", grade=True, locked=True, points=2))
    free = new_code_cell("import numpy as np\nnp.zeros(3)")
    return new_notebook(cells=[intro, answer, tests, free], metadata={
        "kernelspec": {"name": "python3", "language": "python", "display_name": "Python 3"}})


def make_assignment(root: Path, nb: nbformat.NotebookNode | None = None, *,
                    extra: dict[str, str] | None = None) -> Assignment:
    folder = root / "hull"
    files = {
        "assignment.toml": ('[assignment]\nname = "hull"\ntitle = "Hull"\n'
                            'data = ["data/**/*.npy"]\n[rules]\nforbid = ["scipy.spatial"]\n'
                            'reason = "No scipy.spatial."\n[limits]\ncall_timeout = 3\n'),
        "data/points.npy": "public data",
        "data/sub/more.npy": "more public data",
        "checks/public/test_hull.py": PUBLIC_CHECK,
        "checks/public/_shared.py": "DATASETS = {'square': [[0, 0], [1, 0], [1, 1], [0, 1]]}\n",
        "checks/hidden/test_hidden.py": HIDDEN_CHECK,
        "checks/hidden/_secret.py": "SECRET = 'hidden helper'\n",
        "checks/conftest.py": "# shared, never released\n",
        **(extra or {}),
    }
    for relative, text in files.items():
        path = folder / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    nbformat.write(nb if nb is not None else instructor_notebook(), str(folder / "hull.ipynb"))
    return load_assignment(folder)


@pytest.fixture()
def assignment(tmp_path: Path) -> Assignment:
    return make_assignment(tmp_path / "src")


def test_template_has_no_solution_and_keeps_the_stub(assignment: Assignment) -> None:
    nb = student_template(assignment)
    answer = nb.cells[1].source
    assert "BEGIN SOLUTION" not in answer and "secret solution" not in answer
    assert "raise NotImplementedError()" in answer
    assert answer.startswith("def convex_hull(points):\n    # YOUR CODE HERE\n")


def test_template_clears_hidden_tests_and_outputs(assignment: Assignment) -> None:
    nb = student_template(assignment)
    assert nb.cells[2].source.strip() == "assert convex_hull([]) == []"
    assert nb.cells[1].outputs == [] and nb.cells[1].execution_count is None


def test_locked_cells_keep_metadata_and_checksums(assignment: Assignment) -> None:
    nb = student_template(assignment)
    intro, answer, tests = nb.cells[:3]
    assert intro.metadata["deletable"] is False and intro.metadata["editable"] is False
    assert tests.metadata["deletable"] is False and tests.metadata["editable"] is False
    assert answer.metadata["deletable"] is False
    for cell in (intro, answer, tests):
        nbgrader = cell.metadata["nbgrader"]
        assert nbgrader["checksum"] == compute_checksum(cell)
        assert nbgrader["cell_type"] == cell.cell_type
    assert "nbgrader" not in nb.cells[3].metadata


def test_template_does_not_touch_the_instructor_file(assignment: Assignment) -> None:
    before = assignment.notebook.read_bytes()
    student_template(assignment)
    assert assignment.notebook.read_bytes() == before


def test_release_writes_public_files_only(assignment: Assignment, tmp_path: Path) -> None:
    out = tmp_path / "out"
    path = release(assignment, out)
    assert path == out.resolve() / "hull.ipynb" and path.is_file()
    written = {p.relative_to(out.resolve()).as_posix() for p in out.resolve().rglob("*")
               if p.is_file()}
    assert written == {"hull.ipynb", "assignment.toml", "data/points.npy", "data/sub/more.npy",
                       "checks/public/test_hull.py", "checks/public/_shared.py"}
    assert (out / "checks" / "public" / "test_hull.py").read_text() == PUBLIC_CHECK
    text = path.read_text()
    assert "BEGIN SOLUTION" not in text and "secret solution" not in text
    assert "raise NotImplementedError()" in text
    for p in out.rglob("*"):
        if p.is_file():
            assert HIDDEN_LINE not in p.read_text() and "hidden helper" not in p.read_text()


def test_released_folder_loads_as_an_assignment(assignment: Assignment, tmp_path: Path) -> None:
    path = release(assignment, tmp_path / "hull-student")
    released = load_assignment(path.parent)
    assert released.notebook == path and released.hidden_checks == ()
    assert [p.name for p in released.public_checks] == ["test_hull.py"]
    assert released.rules == assignment.rules and released.call_timeout == 3.0
    assert len(released.data_files) == 2


def test_release_refuses_an_out_dir_inside_the_assignment(assignment: Assignment) -> None:
    with pytest.raises(AssignmentError, match="inside the assignment folder"):
        release(assignment, assignment.root / "release")


def test_hidden_check_text_in_the_notebook_is_refused(tmp_path: Path) -> None:
    nb = instructor_notebook()
    nb.cells.append(new_code_cell(f"def test_hidden(student):\n    {HIDDEN_LINE}\n"))
    leaky = make_assignment(tmp_path / "src", nb)
    with pytest.raises(AssignmentError, match="line of a hidden check"):
        student_template(leaky)
    with pytest.raises(AssignmentError, match="Refusing to release"):
        release(leaky, tmp_path / "out")
    assert not (tmp_path / "out" / "hull.ipynb").exists()


def test_hidden_check_copied_as_public_is_refused(tmp_path: Path) -> None:
    leaky = make_assignment(tmp_path / "src", extra={"checks/public/test_copy.py": HIDDEN_CHECK})
    with pytest.raises(AssignmentError, match="copy of checks/hidden/test_hidden.py"):
        release(leaky, tmp_path / "out")
    assert not (tmp_path / "out" / "hull.ipynb").exists()


def test_solution_outside_a_solution_cell_is_refused(tmp_path: Path) -> None:
    nb = instructor_notebook()
    nb.cells.append(new_code_cell("### BEGIN SOLUTION\nx = 1\n### END SOLUTION"))
    with pytest.raises(AssignmentError, match="ClearSolutions"):
        student_template(make_assignment(tmp_path / "src", nb))


def test_unterminated_solution_is_refused(tmp_path: Path) -> None:
    nb = instructor_notebook()
    nb.cells[1].source = "def f():\n    ### BEGIN SOLUTION\n    return 1\n"
    with pytest.raises(AssignmentError, match="no end solution"):
        student_template(make_assignment(tmp_path / "src", nb))


def test_line_shared_with_a_public_check_is_not_a_leak(tmp_path: Path) -> None:
    shared = "assert student.convex_hull([]) == [], 'an empty input has an empty hull'"
    nb = instructor_notebook()
    nb.cells.append(new_code_cell(shared))
    a = make_assignment(tmp_path / "src", nb, extra={
        "checks/public/test_hull.py": f"def test_public(student):\n    {shared}\n",
        "checks/hidden/test_hidden.py": f"{HIDDEN_CHECK}\ndef test_b(student):\n    {shared}\n"})
    assert shared in student_template(a).cells[-1].source
