"""Never a silent zero: another assignment's notebook, the untouched template and deleted
answer cells are each named, and listed under "needs a person"."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import nbformat
import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.identify import identify
from autograder.engine.notebook import parse_notebook, read_notebook
from autograder.errors import UploadRejected
from autograder.results.model import SUBMISSION_NOTE

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
CAR = ROOT / "assignments" / "spline_car"


def released(name: str, target: Path) -> Path:
    """``target``: the released student notebook of ``name`` (``autograder release``'s template)."""
    from autograder.authoring.release import student_template

    target.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(student_template(load_assignment(name)), target)
    return target


def without_cell(source: Path, grade_id: str, target: Path) -> Path:
    nb = nbformat.read(source, as_version=4)
    nb.cells = [c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") != grade_id]
    target.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, target)
    return target


def stripped(source: Path, target: Path) -> Path:
    """``source`` with no cell ids and no nbgrader metadata (as some editors save it)."""
    nb = nbformat.read(source, as_version=4)
    nb.nbformat_minor = 4
    for cell in nb.cells:
        cell.pop("id", None)
        cell.metadata = {}
    target.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, target)
    return target


def test_the_car_notebook_is_not_the_hull_notebook() -> None:
    hull = load_assignment("hull")
    found = identify(read_notebook(CAR / "examples" / "solution.ipynb"), hull)
    assert found.other == "spline_car"
    assert found.problem.startswith("this is the spline_car notebook, not hull")
    assert identify(read_notebook(HULL / "examples" / "solution.ipynb"), hull).other == ""
    assert identify(read_notebook(HULL / "examples" / "solution.ipynb"),
                    load_assignment("spline_car")).other == "hull"


def test_a_notebook_without_metadata_is_known_by_its_name(tmp_path: Path) -> None:
    hull = load_assignment("hull")
    car = stripped(CAR / "examples" / "solution.ipynb", tmp_path / "spline_car.ipynb")
    assert identify(read_notebook(car), hull).other == "spline_car"
    mine = stripped(CAR / "examples" / "solution.ipynb", tmp_path / "alice.ipynb")
    assert identify(read_notebook(mine), hull).other == ""  # no evidence: graded as given


def test_the_untouched_template_and_deleted_cells_get_a_note(tmp_path: Path) -> None:
    hull = load_assignment("hull")
    template = released("hull", tmp_path / "hull.ipynb")
    notes = identify(read_notebook(template), hull).notes
    assert len(notes) == 1 and "released template" in notes[0]
    assert notes[0].startswith(SUBMISSION_NOTE)
    bare = stripped(template, tmp_path / "bare" / "hull.ipynb")  # same code, metadata stripped
    assert "released template" in " ".join(identify(read_notebook(bare), hull).notes)
    gone = without_cell(HULL / "examples" / "solution.ipynb", "convex_hull", tmp_path / "gone.ipynb")
    notes = identify(read_notebook(gone), hull).notes
    assert len(notes) == 1 and "`convex_hull`" in notes[0] and "missing" in notes[0]
    assert identify(read_notebook(HULL / "examples" / "solution.ipynb"), hull).notes == ()


def test_the_service_refuses_another_assignments_notebook() -> None:
    pytest.importorskip("sqlalchemy")
    from autograder.service.course import AssignmentPolicy
    from autograder.service.intake import check_assignment

    import datetime as dt
    policy = AssignmentPolicy(name="hull", spec="hull", title="Convex hull",
                              opens=dt.datetime(2020, 1, 1), deadline=dt.datetime(2099, 1, 1))
    with pytest.raises(UploadRejected) as info:
        check_assignment((CAR / "examples" / "solution.ipynb").read_bytes(), policy, "hull.ipynb")
    assert "spline_car notebook, not hull" in str(info.value) and "Nothing was stored" in str(info.value)
    assert info.value.status == 422
    check_assignment((HULL / "examples" / "solution.ipynb").read_bytes(), policy, "hull.ipynb")
    parse_notebook((HULL / "examples" / "solution.ipynb").read_bytes())


@pytest.mark.slow
def test_wrong_notebooks_in_a_batch_are_never_a_silent_zero(tmp_path: Path) -> None:
    from autograder import api
    from autograder.engine.grader import GradingOptions

    sub = tmp_path / "submitted"
    for student in ("ann", "ben", "cid"):  # the car notebook handed in as hull.ipynb
        target = sub / student / "hull" / "hull.ipynb"
        target.parent.mkdir(parents=True)
        shutil.copy(CAR / "examples" / "solution.ipynb", target)
    released("hull", sub / "dee" / "hull" / "hull.ipynb")
    without_cell(HULL / "examples" / "solution.ipynb", "convex_hull", sub / "eli" / "hull" / "hull.ipynb")
    shutil.copytree(HULL / "examples", sub / "fay" / "hull", ignore=lambda d, names: [
        n for n in names if n != "solution.ipynb"])
    (sub / "fay" / "hull" / "solution.ipynb").rename(sub / "fay" / "hull" / "hull.ipynb")
    out = tmp_path / "out"
    report = api.grade("hull", [sub], out=out, jobs=1, progress=False,
                       options=GradingOptions(public_only=True))
    by_id = {r.id: r for r in report.results}
    assert sorted(by_id) == ["ann", "ben", "cid", "dee", "eli", "fay"]
    for student in ("ann", "ben", "cid"):
        assert by_id[student].outcome == "ungradable"
        assert "this is the spline_car notebook, not hull" in by_id[student].output
    assert by_id["fay"].outcome == "graded" and by_id["fay"].score == by_id["fay"].max_score > 0
    summary = json.loads((out / "summary.json").read_text())
    kinds = {a["id"]: [c["kind"] for c in a["concerns"]] for a in summary["attention"]}
    assert kinds["ann"][0] == "ungradable" and kinds["ben"][0] == "ungradable"
    assert "submission" in kinds["dee"] and "submission" in kinds["eli"]
    assert "fay" not in kinds
    page = (out / "summary.html").read_text()
    assert "spline_car notebook, not hull" in page and "released template" in page
    assert "Nothing needs a person" not in page


def test_the_neighbours_are_read_again_when_they_change(tmp_path: Path) -> None:
    """The assignments beside this one are kept between submissions, never past a change."""
    import os

    from autograder.engine.identify import known_fingerprints

    course = tmp_path / "assignments"
    shutil.copytree(HULL, course / "hull", ignore=shutil.ignore_patterns("examples"))
    shutil.copytree(CAR, course / "spline_car", ignore=shutil.ignore_patterns("examples"))
    hull = load_assignment(course / "hull")
    solution = read_notebook(CAR / "examples" / "solution.ipynb")
    assert [f.name for f in known_fingerprints(hull)] == ["spline_car"]
    assert identify(solution, hull).other == "spline_car"

    # the neighbour's notebook changes (its cells are someone else's now): read again
    notebook = course / "spline_car" / "spline_car.ipynb"
    book = nbformat.read(notebook, as_version=4)
    for k, cell in enumerate(book.cells):
        cell["id"] = f"renamed-{k}"
        cell.metadata.pop("nbgrader", None)
    nbformat.write(book, notebook)
    os.utime(notebook, ns=(1, 2_000_000_000_000_000_000))  # a new stamp, however coarse the clock
    assert identify(solution, hull).other == ""

    # its assignment.toml changes (a broken one is skipped), then the folder goes away
    toml = course / "spline_car" / "assignment.toml"
    toml.write_text("this is not TOML [")
    os.utime(toml, ns=(1, 3_000_000_000_000_000_000))
    assert known_fingerprints(hull) == ()
    shutil.rmtree(course / "spline_car")
    assert known_fingerprints(hull) == ()
