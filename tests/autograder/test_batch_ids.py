"""Readable unique ids, the CSV export and atomic result files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from autograder.batch import assign_ids, collect_submissions
from autograder.errors import UsageError
from autograder.report import grades_csv, read_result, write_result
from autograder.results import CheckResult, SubmissionResult


def test_nbgrader_layout_gets_student_ids() -> None:
    paths = [Path("submitted/alice/hull/hull.ipynb"), Path("submitted/bob/hull/hull.ipynb"),
             Path("late/carol.ipynb")]
    ids = assign_ids(paths)
    assert ids == {paths[0]: "alice-hull", paths[1]: "bob-hull", paths[2]: "carol"}


def test_ids_stay_unique_after_slugging() -> None:
    paths = [Path("a/x y.ipynb"), Path("b/x-y.ipynb")]
    ids = assign_ids(paths)
    assert len(set(ids.values())) == 2


def test_missing_submission_is_a_usage_error(tmp_path: Path) -> None:
    with pytest.raises(UsageError, match="does not exist"):
        collect_submissions([tmp_path / "nope.ipynb"])
    with pytest.raises(UsageError, match="No notebooks"):
        collect_submissions([tmp_path])


def _result(sub_id: str, scores: dict[str, float]) -> SubmissionResult:
    tests = tuple(CheckResult(name=k, score=v, max_score=1.0, output="", hidden=False,
                              kind="ok" if v == 1 else "wrong") for k, v in scores.items())
    return SubmissionResult(id=sub_id, source=f"{sub_id}.ipynb", assignment="hull", key="k",
                            sha256="s", outcome="graded", output="", tests=tests,
                            execution_time=0.1, seed=1)


def test_grades_csv_has_a_column_per_check() -> None:
    text = grades_csv([_result("bob", {"a": 1, "b": 0}), _result("alice", {"a": 0.5, "b": 1})])
    assert text.splitlines() == ["id,score,max_score,outcome,a,b", "alice,1.5,2,graded,0.5,1",
                                 "bob,1,2,graded,1,0"]


def test_results_round_trip_in_gradescope_format(tmp_path: Path) -> None:
    result = _result("alice", {"a": 1, "b": 0})
    write_result(tmp_path / "alice", result)
    data = json.loads((tmp_path / "alice" / "results.json").read_text())
    assert {"score", "max_score", "execution_time", "output", "tests"} <= set(data)
    assert data["tests"][1] == {**data["tests"][1], "status": "failed", "visibility": "visible"}
    assert read_result(tmp_path / "alice") == result
    assert not list((tmp_path / "alice").glob(".*.tmp"))


def test_missing_protections_are_said_once_before_grading(monkeypatch: pytest.MonkeyPatch,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    from autograder import cli
    from autograder.sandbox import IsolationSupport

    note = "Landlock is not available (kernel ABI 0): file and network restrictions are off."
    monkeypatch.setattr(cli, "probe_support",
                        lambda: IsolationSupport(landlock_abi=0, is_root=True,
                                                 can_unshare_net=True, notes=(note,)))
    monkeypatch.setattr(cli, "_check", lambda args: 0)
    assert cli.main(["check", "x.ipynb"]) == 0
    assert capsys.readouterr().err.count(note) == 1
