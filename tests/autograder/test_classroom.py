"""GitHub Classroom's layout (issue 27 point 3): a folder of student repositories as
``gh classroom clone student-repos`` lays them out, graded with the username as id, and
Classroom's roster CSV imported as the course roster."""

from __future__ import annotations

import csv
import io
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from autograder.runners.batch import assign_ids, collect_submissions

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull" / "examples"


def repo(folder: Path, example: str, *, inside: str = "", git: bool = True) -> Path:
    """A student's repository: README, data, the notebook (maybe in a subfolder), ``.git``."""
    folder.mkdir(parents=True)
    (folder / "README.md").write_text("# Convex hull\n")
    target = folder / inside / "hull.ipynb"
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(HULL / f"{example}.ipynb", target)
    if git:  # a .git folder holding a notebook of its own: never a submission
        (folder / ".git" / "objects").mkdir(parents=True)
        (folder / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
        shutil.copy(HULL / "solution.ipynb", folder / ".git" / "stale.ipynb")
    return folder


def classroom(root: Path) -> Path:
    """``<slug>-submissions/<slug>-<username>/``; the slug and a username hold ``-``."""
    sub = root / "convex-hull-submissions"
    repo(sub / "convex-hull-alice", "solution")
    repo(sub / "convex-hull-bob-smith", "wrong-clockwise", inside="work")
    repo(sub / "convex-hull-carol", "solution", git=False)  # a download without .git
    return sub


def test_the_repositories_are_the_submissions_and_the_usernames_the_ids(tmp_path: Path) -> None:
    sub = classroom(tmp_path)
    expected = {sub / f"convex-hull-{u}": u for u in ("alice", "bob-smith", "carol")}
    for given in (sub, tmp_path):  # the clone folder, or the folder holding it
        found = collect_submissions([given], "hull")
        assert found == sorted(expected)
        assert assign_ids(found) == expected
    one = collect_submissions([sub / "convex-hull-alice"], "hull")
    assert assign_ids(one) == {sub / "convex-hull-alice": "alice"}


def test_cloned_elsewhere_the_shared_prefix_is_the_slug(tmp_path: Path) -> None:
    """``gh classroom clone student-repos -d classroom`` renamed by hand: no ``-submissions``."""
    root = tmp_path / "classroom"
    for user in ("alice", "bob-smith"):
        repo(root / f"hw-1-{user}", "solution")
    found = collect_submissions([root], "hull")
    assert assign_ids(found) == {root / "hw-1-alice": "alice", root / "hw-1-bob-smith": "bob-smith"}


def test_nbgrader_layout_inside_a_git_repository_is_still_nbgrader(tmp_path: Path) -> None:
    """A course kept in git: its submitted/ folder is read as nbgrader's, not as repositories."""
    (tmp_path / ".git").mkdir()
    sub = tmp_path / "submitted"
    for student in ("alice", "bob"):
        (sub / student / "hull").mkdir(parents=True)
        shutil.copy(HULL / "solution.ipynb", sub / student / "hull" / "hull.ipynb")
    found = collect_submissions([tmp_path], "hull")
    assert assign_ids(found) == {sub / s / "hull": s for s in ("alice", "bob")}


@pytest.mark.slow
def test_grade_a_classroom_folder_end_to_end(tmp_path: Path) -> None:
    sub = classroom(tmp_path)
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "autograder", "grade", "hull", str(sub),
                           "--out", str(out), "--jobs", "1"], cwd=ROOT, capture_output=True,
                          text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    grades = {r["id"]: r for r in csv.DictReader(io.StringIO((out / "grades.csv").read_text()))}
    assert set(grades) == {"alice", "bob-smith", "carol"}
    assert float(grades["alice"]["score"]) == float(grades["alice"]["max_score"]) > 0
    assert float(grades["bob-smith"]["score"]) < float(grades["bob-smith"]["max_score"])


#: GitHub Classroom's roster download: every student of the course, linked or not yet
CLASSROOM_ROSTER = ('"identifier","github_username","github_id","name"\n'
                    '"alice@uni.example","alice","1001","Alice A."\n'
                    '"s-2002","bob-smith","1002",""\n'
                    '"carol@uni.example","","",""\n')


def test_classroom_roster_gives_the_usernames_as_ids(tmp_path: Path) -> None:
    from autograder.service.auth import read_roster, unlinked_rows

    roster = tmp_path / "classroom_roster.csv"
    roster.write_text(CLASSROOM_ROSTER)
    entries = {e.id: e for e in read_roster(roster)}
    assert set(entries) == {"alice", "bob-smith"}  # the ids the repositories' folders give
    assert (entries["alice"].name, entries["alice"].email) == ("Alice A.", "alice@uni.example")
    assert (entries["bob-smith"].name, entries["bob-smith"].email) == ("s-2002", "")
    assert {e.role for e in entries.values()} == {"student"}
    assert unlinked_rows(roster) == ("carol@uni.example",)


def test_roster_command_imports_classroom_roster_and_names_the_unlinked(tmp_path: Path) -> None:
    (tmp_path / "roster.csv").write_text("id,name,email,role\nteacher,T,t@uni.example,instructor\n")
    course = tmp_path / "course.toml"
    course.write_text('[course]\nname = "Classroom course"\nroster = "roster.csv"\ndata = "data"\n'
                      '[[assignment]]\nname = "hull"\nopens = 2020-01-01T00:00:00Z\n'
                      'deadline = 2030-01-01T00:00:00Z\n')
    roster = tmp_path / "classroom_roster.csv"
    roster.write_text(CLASSROOM_ROSTER)
    tokens = tmp_path / "tokens.csv"
    done = subprocess.run([sys.executable, "-m", "autograder", "roster", str(course), str(roster),
                           "--database", f"sqlite:///{tmp_path / 'db.sqlite3'}", "--tokens",
                           str(tokens)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "carol@uni.example" in done.stdout and "no GitHub account linked" in done.stdout
    issued = {r["id"] for r in csv.DictReader(io.StringIO(tokens.read_text()))}
    assert {"alice", "bob-smith"} <= issued and "carol@uni.example" not in issued
