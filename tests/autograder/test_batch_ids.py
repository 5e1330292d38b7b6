"""Readable unique ids, the CSV export and atomic result files."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from autograder.errors import UsageError
from autograder.results.files import atomic_write_text
from autograder.results.model import CheckResult, SubmissionResult
from autograder.results.store import grades_csv, read_result, write_result
from autograder.runners.batch import (
    RESERVED_NAMES,
    Shard,
    assign_ids,
    collect_submissions,
    place_name,
)


def test_nbgrader_layout_gets_student_ids() -> None:
    paths = [Path("submitted/alice/hull/hull.ipynb"), Path("submitted/bob/hull/hull.ipynb"),
             Path("late/carol.ipynb")]
    ids = assign_ids(paths)
    assert ids == {paths[0]: "alice", paths[1]: "bob", paths[2]: "carol"}


def test_one_file_in_nbgrader_layout_gets_the_same_id_as_in_the_folder() -> None:
    alone = Path("/course/submitted/alice/hull/hull.ipynb")
    assert assign_ids([alone]) == {alone: "alice"}
    assert place_name(alone) == "alice" and place_name(Path("/x/hull.ipynb")) == "hull"


def test_two_notebooks_of_one_student_keep_apart() -> None:
    paths = [Path("submitted/alice/hull/hull.ipynb"), Path("submitted/alice/hull/extra.ipynb")]
    assert sorted(assign_ids(paths).values()) == ["alice+extra", "alice+hull"]
    flat = [Path("a/x.ipynb"), Path("b/x.ipynb")]
    assert sorted(assign_ids(flat).values()) == ["x+a", "x+b"]


@pytest.mark.parametrize("name", ["grades.csv", "summary", "summary.html", "summary.json", "GRADES.CSV",
                                  "junit.xml", "images"])
def test_ids_never_clash_with_the_batch_files(name: str) -> None:
    paths = [Path(f"in/{name}.ipynb"), Path(f"in/{name}.ipynb.ipynb"), Path("in/grades.csv-submission.ipynb")]
    ids = assign_ids(paths)
    assert len(set(ids.values())) == 3
    assert not {i.lower() for i in ids.values()} & RESERVED_NAMES


def test_shards_split_ids_deterministically() -> None:
    ids = [f"student{i:03d}" for i in range(300)]
    shards = [Shard.parse(f"{k}/3") for k in range(3)]
    owners = [[s.holds(i) for s in shards].count(True) for i in ids]
    assert owners == [1] * len(ids)
    sizes = [sum(s.holds(i) for i in ids) for s in shards]
    assert min(sizes) > 60  # a hash, not a range: every shard gets a fair share
    # stable across processes and machines: SHA-256 of the id, not Python's hash()
    names = ("alice", "bob", "carol", "dave", "erin", "frank")
    assert [next(k for k, s in enumerate(shards) if s.holds(n)) for n in names] == [2, 2, 2, 1, 0, 2]
    for bad in ("3/3", "1", "a/b", "-1/2", "0/0"):
        with pytest.raises(UsageError, match="K/N"):
            Shard.parse(bad)


def test_result_files_follow_the_umask(tmp_path: Path) -> None:
    previous = os.umask(0o027)
    try:
        write_result(tmp_path / "alice", _result("alice", {"a": 1}))
        atomic_write_text(tmp_path / "grades.csv", "id\n")
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "alice" / "results.json").stat().st_mode) == 0o640
    assert stat.S_IMODE((tmp_path / "grades.csv").stat().st_mode) == 0o640
    previous = os.umask(0o022)
    try:
        atomic_write_text(tmp_path / "grades.csv", "id\n")
    finally:
        os.umask(previous)
    assert stat.S_IMODE((tmp_path / "grades.csv").stat().st_mode) == 0o644


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


def test_missing_protections_are_said_once_after_the_launch_before_grading(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from autograder import cli
    from autograder.sandbox.support import IsolationSupport

    note = "Landlock is not available (kernel ABI 0): file and network restrictions are off."
    events: list[str] = []

    def probe_support() -> IsolationSupport:  # what the note is made of, printed next
        events.append("probed")
        return IsolationSupport(landlock_abi=0, is_root=True, can_unshare_net=True,
                                notes=(note,))

    class Started:  # what slot.start_early returns: the warm parent launched
        def __enter__(self) -> None:
            return None

        def __exit__(self, *exc: object) -> None:
            events.append("shut down")

    def start_early(**kwargs: object) -> Started:
        events.append("launched")
        return Started()

    monkeypatch.setattr("autograder.sandbox.support.probe_support", probe_support)
    monkeypatch.setattr("autograder.engine.slot.start_early", start_early)
    monkeypatch.setattr("autograder.api.check", lambda *a, **kw: (_ for _ in ()).throw(
        cli.UsageError("stop here")))
    assert cli.main(["check", "x.ipynb"]) == 2
    assert capsys.readouterr().err.count(note) == 1
    assert events == ["launched", "probed", "shut down"], events


# -- the class folder and shards, end to end (local backend, public checks only) ----------------

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def class_folder(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[Path], Path]:
    """Three submissions graded together into one folder."""
    import shutil

    from autograder import api
    from autograder.engine.grader import GradingOptions

    subs = tmp_path_factory.mktemp("subs")
    for source in (ROOT / "assignments/hull/examples/solution.ipynb",
                   ROOT / "assignments/hull/examples/wrong-clockwise.ipynb",
                   ROOT / "tests/files/problems/no-code.ipynb"):
        shutil.copy(source, subs / source.name)
    out = tmp_path_factory.mktemp("whole")
    api.grade("hull", [subs], out=out, jobs=1, options=GradingOptions(public_only=True), progress=False)
    return sorted(subs.iterdir()), out


@pytest.mark.slow
def test_shards_merged_equal_the_whole_run(class_folder: tuple[list[Path], Path], tmp_path: Path) -> None:
    from autograder import api
    from autograder.engine.grader import GradingOptions

    subs, whole = class_folder
    folders = []
    for k in range(3):
        folders.append(tmp_path / f"shard{k}")
        report = api.grade("hull", subs, out=folders[-1], jobs=1, shard=f"{k}/3",
                           options=GradingOptions(public_only=True), progress=False)
        assert report.other_shards == len(subs) - len(report.results)
    assert sum(len(list(f.glob("*/results.json"))) for f in folders) == len(subs)
    merged = api.merge(folders, out=tmp_path / "merged", junit=tmp_path / "junit.xml")
    assert len(merged.results) == len(subs)
    assert (tmp_path / "merged" / "grades.csv").read_text() == (whole / "grades.csv").read_text()
    untimed = [{k: v for k, v in json.loads((folder / "summary.json").read_text()).items()
                if "seconds" not in k} for folder in (tmp_path / "merged", whole)]
    assert untimed[0] == untimed[1]  # the same class summary, but for how long each shard took
    assert all((tmp_path / "merged" / r.id / "feedback.html").is_file() for r in merged.results)
    assert (tmp_path / "junit.xml").read_text().count("<testsuite ") == len(subs)


@pytest.mark.slow
def test_one_late_file_into_the_class_folder_exports_what_was_given(class_folder: tuple[list[Path], Path],
                                                             tmp_path: Path) -> None:
    import shutil

    from autograder import api
    from autograder.engine.grader import GradingOptions

    subs, whole = class_folder
    out = tmp_path / "class"
    shutil.copytree(whole, out)
    late = tmp_path / "submitted" / "alice" / "hull" / "hull.ipynb"
    late.parent.mkdir(parents=True)
    shutil.copy(ROOT / "assignments/hull/examples/solution.ipynb", late)
    previous = os.umask(0o027)
    try:
        report = api.grade("hull", [late], out=out, jobs=1, options=GradingOptions(public_only=True),
                           progress=False, junit=out / "junit.xml")
    finally:
        os.umask(previous)
    assert [r.id for r in report.results] == ["alice"]  # the student's folder names the row
    rows = (out / "grades.csv").read_text().splitlines()
    # the exports list exactly the submissions given; the others stay on disk, listed apart
    assert [r.split(",")[0] for r in rows[1:]] == ["alice"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["submissions"] == 1
    assert [g["id"] for g in summary["no_longer_submitted"]] == ["no-code", "solution",
                                                                 "wrong-clockwise"]
    assert all((out / i / "results.json").exists() for i in ("no-code", "solution"))
    assert (out / "junit.xml").read_text().count("<testsuite ") == 1
    assert stat.S_IMODE((out / "alice" / "results.json").stat().st_mode) == 0o640
    with pytest.raises(UsageError, match="folder of its own"):
        api.grade("bezier", [late], out=out, jobs=1, progress=False)
