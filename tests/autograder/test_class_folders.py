"""The class folder read as the instructor laid it out, ids that never collapse, and exports
that list exactly the submissions given (issue 25 points 5 and 6, issue 24 point 6)."""

from __future__ import annotations

import csv
import io
import json
import shutil
from pathlib import Path

import pytest

from autograder.runners.batch import assign_ids, collect_submissions, escape_id

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull" / "examples"
CAR = ROOT / "assignments" / "spline_car" / "examples"
NO_CODE = ROOT / "tests" / "files" / "problems" / "no-code.ipynb"


def _put(source: Path, target: Path) -> Path:
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(source, target)
    return target


def mixed_class(root: Path) -> Path:
    """nbgrader's ``submitted/<student>/<assignment>/``: two assignments per student, a
    checkpoint copy and a stray copy for alice, carol with hull only, dave with the car only."""
    sub = root / "submitted"
    for student, hull, car in (("alice", "solution", "solution"), ("bob", "wrong-clockwise", "wrong-linear")):
        _put(HULL / f"{hull}.ipynb", sub / student / "hull" / "hull.ipynb")
        _put(CAR / f"{car}.ipynb", sub / student / "spline_car" / "spline_car.ipynb")
    _put(NO_CODE, sub / "alice" / "hull" / ".ipynb_checkpoints" / "hull-checkpoint.ipynb")
    _put(HULL / "wrong-clockwise.ipynb", sub / "alice" / "hull" / "hull-Copy1.ipynb")
    _put(HULL / "solution.ipynb", sub / "carol" / "hull" / "hull.ipynb")
    _put(CAR / "solution.ipynb", sub / "dave" / "spline_car" / "spline_car.ipynb")
    return sub


def rows(out: Path) -> dict[str, dict[str, str]]:
    return {r["id"]: r for r in csv.DictReader(io.StringIO((out / "grades.csv").read_text()))}


def test_the_class_folder_gives_one_submission_per_student_of_that_assignment(tmp_path: Path) -> None:
    sub = mixed_class(tmp_path)
    found = collect_submissions([sub], "hull")
    assert found == [sub / s / "hull" for s in ("alice", "bob", "carol")]
    assert assign_ids(found) == {sub / s / "hull": s for s in ("alice", "bob", "carol")}
    assert collect_submissions([sub], "spline_car") == [sub / s / "spline_car" for s in ("alice", "bob", "dave")]
    # the folder holding submitted/ reads it the same way
    assert collect_submissions([tmp_path], "hull") == [sub / s / "hull" for s in ("alice", "bob", "carol")]
    # one student's folder, or one assignment folder, gives the same id
    assert assign_ids(collect_submissions([sub / "alice"], "hull")) == {sub / "alice" / "hull": "alice"}
    assert assign_ids(collect_submissions([sub / "bob" / "hull"], "hull")) == {sub / "bob" / "hull": "bob"}


@pytest.mark.parametrize("names", [
    ["alice", "alice!", "alice "],
    ["a b", "a-b", "a_b", "a~20b", "a+b"],
    ["grades.csv", "grades.csv+", ".hidden", "~hidden", "élodie", "ÉLODIE"],
])
def test_distinct_names_get_distinct_ids(names: list[str]) -> None:
    paths = [Path("flat") / f"{n}.ipynb" for n in names]
    ids = assign_ids(paths)
    assert len(set(ids.values())) == len(names)
    assert all(not i.startswith(".") and "/" not in i for i in ids.values())
    assert ids[paths[0]] == escape_id(names[0]) or names[0] == "grades.csv"


def test_ids_are_readable() -> None:
    assert [escape_id(n) for n in ("alice", "alice!", "alice ", "a.b-c_d", "..", "a/b")] == [
        "alice", "alice~21", "alice~20", "a.b-c_d", "~2E.", "a~2Fb"]


@pytest.mark.slow
def test_a_mixed_class_folder_then_a_rerun_with_the_right_folder(tmp_path: Path) -> None:
    from autograder import api
    from autograder.engine.grader import GradingOptions
    from autograder.results.model import SubmissionResult
    from autograder.results.store import write_submission

    sub = mixed_class(tmp_path)
    out = tmp_path / "out"
    # what the old id scheme left behind: rows of the car notebooks graded against hull
    for stale in ("alice-spline_car", "bob-spline_car"):
        write_submission(out / stale, SubmissionResult(
            id=stale, source=str(sub / stale.split("-")[0] / "spline_car" / "spline_car.ipynb"),
            assignment="hull", key="old", sha256="", outcome="graded", output="", tests=(),
            execution_time=0.0, seed=0), title="hull")
    options = GradingOptions(public_only=True)
    report = api.grade("hull", [sub], out=out, jobs=1, progress=False, options=options)
    assert sorted(r.id for r in report.results) == ["alice", "bob", "carol"]
    by_id = {r.id: r for r in report.results}
    assert by_id["alice"].outcome == "graded" and by_id["alice"].score == by_id["alice"].max_score > 0
    assert any("hull-Copy1.ipynb" in n for n in by_id["alice"].notes)
    assert not any("checkpoint" in n for n in by_id["alice"].notes)
    assert sorted(rows(out)) == ["alice", "bob", "carol"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["submissions"] == 3
    assert sorted(g["id"] for g in summary["no_longer_submitted"]) == ["alice-spline_car", "bob-spline_car"]
    assert (out / "alice-spline_car" / "results.json").exists()  # kept on disk
    attention = {a["id"]: [c["kind"] for c in a["concerns"]] for a in summary["attention"]}
    assert attention.get("alice") == ["submission"]
    assert "no longer submitted" in (out / "summary.html").read_text().lower()
    # the rerun with only alice and bob: carol's row leaves the exports, nothing is regraded
    again = api.grade("hull", [sub / "alice", sub / "bob"], out=out, jobs=1, progress=False,
                      options=options, junit=out / "junit.xml")
    assert again.graded == 0 and again.reused == 2
    assert sorted(rows(out)) == ["alice", "bob"]
    summary = json.loads((out / "summary.json").read_text())
    assert "carol" in {g["id"] for g in summary["no_longer_submitted"]}
    assert (out / "junit.xml").read_text().count("<testsuite ") == 2


@pytest.mark.slow
def test_ids_never_collapse_and_a_rerun_never_overwrites_another_file(tmp_path: Path) -> None:
    from autograder import api
    from autograder.engine.grader import GradingOptions
    from autograder.results.store import read_result

    options = GradingOptions(public_only=True)
    out = tmp_path / "out"
    first = tmp_path / "first"
    _put(HULL / "solution.ipynb", first / "alice.ipynb")
    _put(NO_CODE, first / "alice!.ipynb")
    report = api.grade("hull", [first], out=out, jobs=1, progress=False, options=options)
    assert sorted(r.id for r in report.results) == ["alice", "alice~21"]
    full = read_result(out / "alice")
    assert full is not None and full.score == full.max_score > 0
    # a later run with "alice .ipynb": its own id, alice's full marks stay
    later = tmp_path / "later"
    _put(NO_CODE, later / "alice .ipynb")
    report = api.grade("hull", [later], out=out, jobs=1, progress=False, options=options)
    assert [r.id for r in report.results] == ["alice~20"]
    assert read_result(out / "alice") == full
    # another alice.ipynb from another folder, while the first still exists: a conflict
    other = _put(NO_CODE, tmp_path / "other" / "alice.ipynb")
    report = api.grade("hull", [other.parent], out=out, jobs=1, progress=False, options=options)
    assert report.conflicts == (("alice", str(other)),) and report.results == ()
    assert read_result(out / "alice") == full  # never overwritten
    summary = json.loads((out / "summary.json").read_text())
    assert summary["conflicts"] == [{"id": "alice", "source": str(first / "alice.ipynb"),
                                     "claimed_by": str(other)}]
    assert "alice" not in rows(out)
    assert "Id conflicts" in (out / "summary.html").read_text()
    # the first folder moved: the result follows its file, no conflict, nothing regraded
    moved = tmp_path / "moved"
    first.rename(moved)
    report = api.grade("hull", [moved], out=out, jobs=1, progress=False, options=options)
    assert report.conflicts == () and report.reused == 2 and report.graded == 0
    assert read_result(out / "alice").source == str(moved / "alice.ipynb")
    assert sorted(rows(out)) == ["alice", "alice~21"]
