"""Per-student variants: release, grading, answers that travel, students with no variant.

The assignment is written here from scratch: ``scaled(x)`` multiplies by the
student's parameter ``a`` (set by the notebook's parameters cell); the hidden
check computes the expected value on the trusted side from the variant.
"""

from __future__ import annotations

import json
from pathlib import Path

import nbformat
import pytest

from autograder.authoring.release import release_variants
from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from autograder.errors import AssignmentError
from autograder.results.summary import needs_attention

SOLUTION = "def scaled(x):\n    return a * x\n"
CHECK = '''\
import pytest


@pytest.mark.visibility("input")
def test_scaled(student, variant, feedback):
    feedback.input("x = 10")
    got = student.scaled(10)
    variant.record("answer", got)
    assert got == variant["a"] * 10, f"expected {variant['a'] * 10}, got {got}"
'''
HOOK = "def answers(params):\n    return {'answer': params['a'] * 10}\n"


def write_scaled(root: Path, *, roster: tuple[str, ...] = ("ada", "bob")) -> Path:
    folder = root / "scaled"
    (folder / "checks" / "hidden").mkdir(parents=True)
    (folder / "checks" / "public").mkdir(parents=True)
    (folder / "assignment.toml").write_text(
        '[assignment]\nname = "scaled"\n'
        '[variants]\nroster = "roster.csv"\n'
        '[variants.params.a]\nkind = "int"\nlow = 2\nhigh = 1000\n'
        '[variants.fixed.example]\na = 3\n')
    (folder / "roster.csv").write_text("identifier,github_username\n"
                                       + "".join(f"{s}@uni,{s}\n" for s in roster))
    (folder / "variants.py").write_text(HOOK)
    (folder / "checks" / "hidden" / "test_scaled.py").write_text(CHECK)
    params = nbformat.v4.new_code_cell("a = 3\n", metadata={"tags": ["variant"]})
    solution = nbformat.v4.new_code_cell(
        "### BEGIN SOLUTION\n" + SOLUTION + "### END SOLUTION\nprint(scaled(10))",
        metadata={"nbgrader": {"grade_id": "scaled", "solution": True, "grade": False,
                               "locked": False, "schema_version": 3}})
    nbformat.write(nbformat.v4.new_notebook(cells=[params, solution]), folder / "scaled.ipynb")
    return folder


def answered(path: Path, code: str) -> Path:
    """The released notebook at ``path`` with its solution cell replaced by ``code``."""
    nb = nbformat.read(str(path), as_version=4)
    nb.cells[1].source = code
    nbformat.write(nb, str(path))
    return path


@pytest.fixture
def secret(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", "course secret for the tests")


def test_release_writes_one_notebook_per_student_with_their_parameters(tmp_path: Path,
                                                                      secret: None) -> None:
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    written = release_variants(assignment, assignment.root / "roster.csv", tmp_path / "out")
    assert [p.relative_to(tmp_path / "out").as_posix() for p in written] == [
        "ada/scaled.ipynb", "bob/scaled.ipynb"]
    values = [assignment.variants.draw("scaled", s)["a"] for s in ("ada", "bob")]
    assert values[0] != values[1]
    for path, value in zip(written, values):
        cells = nbformat.read(str(path), as_version=4).cells
        assert f"a = {value}" in cells[0].source
        assert "### BEGIN SOLUTION" not in cells[1].source and "a * x" not in cells[1].source


def test_the_seed_depends_on_the_course_secret(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", "one")
    first = assignment.variants.seed("scaled", "ada")
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", "two")
    assert assignment.variants.seed("scaled", "ada") != first


def test_both_right_both_full_marks_and_a_travelling_answer_is_flagged(tmp_path: Path,
                                                                       secret: None) -> None:
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    ada, bob = release_variants(assignment, assignment.root / "roster.csv", tmp_path / "out")
    ada_a = assignment.variants.draw("scaled", "ada")["a"]
    answered(ada, SOLUTION)
    answered(bob, SOLUTION)
    with Grader(assignment) as grader:
        right = [grader.grade(p, id=s, out_dir=tmp_path / "results" / s)
                 for p, s in ((ada, "ada"), (bob, "bob"))]
        # bob copies ada's printed answer instead of computing his own
        (tmp_path / "copy").mkdir()
        copy = tmp_path / "copy" / "scaled.ipynb"
        copy.write_bytes(bob.read_bytes())
        answered(copy, f"def scaled(x):\n    return {ada_a * 10}\n")
        copied = grader.grade(copy, id="bob", out_dir=tmp_path / "results" / "bob-copy")
    assert [r.score for r in right] == [1.0, 1.0] and [r.max_score for r in right] == [1.0, 1.0]
    assert not needs_attention(right)
    assert copied.score == 0.0
    flagged = needs_attention([copied])
    assert len(flagged) == 1
    evidence = " ".join(c.detail for c in flagged[0].concerns)
    assert "ada's variant" in evidence and str(ada_a * 10) in evidence
    stored = json.loads((tmp_path / "results" / "ada" / "results.json").read_text())
    assert stored["extra_data"]["variant"] == {
        "student": "ada", "seed": assignment.variants.seed("scaled", "ada"),
        "params": {"a": ada_a}}
    assert stored["tests"][0]["extra_data"]["observed"] == {"answer": ada_a * 10}


def test_an_id_without_a_variant_waits_for_a_person(tmp_path: Path, secret: None) -> None:
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    ada, = release_variants(assignment, assignment.root / "roster.csv", tmp_path / "out")[:1]
    answered(ada, SOLUTION)
    with Grader(assignment) as grader:
        result = grader.grade(ada, id="stranger")
    assert [t.kind for t in result.tests] == ["needs-person"]
    assert "not on the roster" in result.tests[0].output
    assert "wait for a person" in result.output
    flagged = needs_attention([result])
    assert flagged and "not on the roster" in " ".join(c.detail for c in flagged[0].concerns)


def test_a_fixed_id_grades_the_instructor_values(tmp_path: Path, secret: None) -> None:
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    ada = release_variants(assignment, assignment.root / "roster.csv", tmp_path / "out")[0]
    answered(ada, "a = 3\n" + SOLUTION)  # the example's notebook keeps the instructor's a = 3
    with Grader(assignment) as grader:
        assert grader.grade(ada, id="example").score == 1.0


@pytest.mark.parametrize("table, message", [
    ('[variants]\n', "declares no parameter"),
    ('[variants.params.n]\nkind = "int"\nlow = 1\n', "needs low, high"),
    ('[variants.params.n]\nkind = "normal"\n', "kind = one of"),
    ('[variants]\nroster = "nobody.csv"\n[variants.params.n]\nkind = "choice"\nvalues = [1]\n',
     "was not found"),
])
def test_a_wrong_variants_table_names_the_mistake(tmp_path: Path, table: str, message: str) -> None:
    folder = write_scaled(tmp_path / "src")
    (folder / "variants.py").unlink()
    (folder / "assignment.toml").write_text('[assignment]\nname = "scaled"\n' + table)
    with pytest.raises(AssignmentError, match=message):
        load_assignment(folder)


def test_release_without_a_parameters_cell_says_so(tmp_path: Path, secret: None) -> None:
    folder = write_scaled(tmp_path / "src")
    nb = nbformat.read(str(folder / "scaled.ipynb"), as_version=4)
    nb.cells[0].metadata = {}
    nbformat.write(nb, str(folder / "scaled.ipynb"))
    with pytest.raises(AssignmentError, match="tagged 'variant'"):
        release_variants(load_assignment(folder), folder / "roster.csv", tmp_path / "out")


def test_without_the_secret_every_id_has_the_instructors_values(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NUMGRADE_VARIANT_SECRET", raising=False)
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    for student in ("ada", "stranger"):  # on the roster or not: variants are off
        variant = assignment.variants.lookup("scaled", student)
        assert variant is not None and variant.to_dict() == {
            "student": student, "seed": None, "params": {"a": 3}}
    with pytest.raises(AssignmentError, match="NUMGRADE_VARIANT_SECRET is not set"):
        release_variants(assignment, assignment.root / "roster.csv", tmp_path / "out")
    assert not (tmp_path / "out").exists()
    ada = tmp_path / "ada.ipynb"
    ada.write_bytes((assignment.root / "scaled.ipynb").read_bytes())
    answered(ada, SOLUTION)
    with Grader(assignment) as grader:
        result = grader.grade(ada, id="ada")
    assert result.score == 1.0 and result.variant == {"student": "ada", "seed": None,
                                                      "params": {"a": 3}}


def test_a_list_of_fixed_ids_gets_the_parameters_cell_as_written(tmp_path: Path,
                                                                 secret: None) -> None:
    folder = write_scaled(tmp_path / "src")
    toml = folder / "assignment.toml"
    toml.write_text(toml.read_text().replace('[variants.fixed.example]\na = 3\n', '')
                    .replace('roster = "roster.csv"\n',
                             'roster = "roster.csv"\nfixed = ["example", "solution"]\n'))
    spec = load_assignment(folder).variants
    assert spec.instructor == (("a", 3),)
    assert spec.lookup("scaled", "solution").to_dict() == {
        "student": "solution", "seed": None, "params": {"a": 3}}
    assert spec.lookup("scaled", "ada")["a"] == spec.draw("scaled", "ada")["a"]
    nb = nbformat.read(str(folder / "scaled.ipynb"), as_version=4)
    nb.cells[0].metadata = {}  # no parameters cell: the list has no values to give
    nbformat.write(nb, str(folder / "scaled.ipynb"))
    with pytest.raises(AssignmentError, match="no code cell tagged 'variant'"):
        load_assignment(folder)


@pytest.mark.parametrize("cell, message", [
    ("a = 3\nb = len('xy')\n", "line 2 is not one"),
    ("a = (\n", "is not valid Python"),
])
def test_a_parameters_cell_of_code_names_the_line(tmp_path: Path, cell: str,
                                                  message: str) -> None:
    folder = write_scaled(tmp_path / "src")
    nb = nbformat.read(str(folder / "scaled.ipynb"), as_version=4)
    nb.cells[0].source = cell
    nbformat.write(nb, str(folder / "scaled.ipynb"))
    with pytest.raises(AssignmentError, match=message):
        load_assignment(folder)


def test_a_notebook_released_with_variants_but_graded_without_the_secret_is_flagged(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", "course secret for the tests")
    assignment = load_assignment(write_scaled(tmp_path / "src"))
    ada, bob = release_variants(assignment, assignment.root / "roster.csv", tmp_path / "out")
    answered(ada, SOLUTION)
    (tmp_path / "copy").mkdir()
    copy = tmp_path / "copy" / "scaled.ipynb"  # bob hands in ada's notebook
    copy.write_bytes(ada.read_bytes())
    with Grader(assignment) as grader:
        copied = grader.grade(copy, id="bob")
    evidence = " ".join(c.detail for c in needs_attention([copied])[0].concerns)
    assert "parameters cell holds ada's variant" in evidence
    monkeypatch.delenv("NUMGRADE_VARIANT_SECRET")
    with Grader(load_assignment(assignment.root)) as grader:
        result = grader.grade(ada, id="ada")  # ada's own a, graded with the instructor's a = 3
    flagged = needs_attention([result])
    assert flagged and "NUMGRADE_VARIANT_SECRET is not set here" in " ".join(
        c.detail for c in flagged[0].concerns)


def test_a_submitted_parameters_cell_is_read_only_within_the_notebook_limit(
        tmp_path: Path) -> None:
    from autograder.engine.variants import submitted_values
    book = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell("a = 7", metadata={"tags": ["variant"]}),
        nbformat.v4.new_markdown_cell("x" * 50_000)])
    path = tmp_path / "scaled.ipynb"
    nbformat.write(book, str(path))
    size = path.stat().st_size
    assert submitted_values(path, "variant", max_bytes=size) == {"a": 7}
    # over the grader's limit (which refuses the file anyway): not parsed, no evidence
    assert submitted_values(path, "variant", max_bytes=size - 1) is None
