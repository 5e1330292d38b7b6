"""The shipped hull assignment with per-student boards of pins (``assignments/hull/variants.py``).

Fast tests: every drawn board is a fair problem, the examples and a machine without
the course secret get the instructor's board. Slow tests run the real command line a
teacher runs: ``release --variants``, two honest students and a copier, ``grade``.
"""

from __future__ import annotations

import ast
import html
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import nbformat
import numpy as np
import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from reference import convex_hull

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
SECRET = "the hull variants test's course secret"
INSTRUCTOR_PINS = np.loadtxt(HULL / "data" / "pins.csv", delimiter=",", skiprows=1).tolist()


@pytest.fixture
def secret(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", SECRET)


def hook() -> ModuleType:
    """The assignment's ``variants.py``, imported from its file as the grader does."""
    spec = importlib.util.spec_from_file_location("hull_variants_under_test",
                                                  HULL / "variants.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_board_is_a_fair_problem_of_its_own(secret: None) -> None:
    spec = load_assignment(HULL).variants
    assert spec is not None and spec.active()
    module = hook()
    boards = [np.array(spec.draw("hull", f"student{k}")["pins"]) for k in range(40)]
    for board in boards:
        assert board.shape == (31, 2)
        assert np.all(board * 4 == np.round(board * 4))  # the quarter-centimetre grid
        assert board[:, 0].min() >= 1.0 and board[:, 0].max() <= 9.5
        assert board[:, 1].min() >= 0.5 and board[:, 1].max() <= 7.5
        hull = [int(i) for i in convex_hull(board)]
        assert len(np.unique(board, axis=0)) == 31 and 7 <= len(hull) <= 9
        assert module.edge_pins(board, hull) in (1, 2)
        assert np.sum(board[:, 0] == board[:, 0].min()) == 1
    assert len({b.tobytes() for b in boards}) == len(boards)
    # the instructor's board (data/pins.csv) has the same features
    assert module.is_fair(np.array(INSTRUCTOR_PINS))


def test_the_draw_depends_on_the_student_and_the_secret_only(
        monkeypatch: pytest.MonkeyPatch) -> None:
    spec = load_assignment(HULL).variants
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", "one")
    first = spec.draw("hull", "alice")
    assert spec.draw("hull", "alice") == first
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", "two")
    assert spec.draw("hull", "alice")["pins"] != first["pins"]


def test_examples_and_a_machine_without_the_secret_get_the_instructors_board(
        monkeypatch: pytest.MonkeyPatch) -> None:
    spec = load_assignment(HULL).variants
    monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", SECRET)
    for example in ("solution", "template", "wrong-clockwise"):
        fixed = spec.lookup("hull", example)
        assert fixed is not None and fixed.seed is None and fixed["pins"] == INSTRUCTOR_PINS
    assert spec.lookup("hull", "mallory") is None  # not on assignments/hull/roster.csv
    monkeypatch.delenv("NUMGRADE_VARIANT_SECRET")
    for anyone in ("alice", "mallory"):
        own = spec.lookup("hull", anyone)
        assert own is not None and own.seed is None and own["pins"] == INSTRUCTOR_PINS


@pytest.mark.slow
def test_the_same_wrong_code_loses_the_same_points_on_every_board(secret: None) -> None:
    """Fair boards: a march that keeps edge pins earns half of the board check on any board."""
    assignment = load_assignment(HULL)
    notebook = HULL / "examples" / "wrong-keeps-collinear.ipynb"
    with Grader(assignment) as grader:
        results = [grader.grade(notebook, id=s) for s in ("alice", "bob", "dave")]
    board = [next(t for t in r.tests if t.name == "convex_hull_your_pins") for r in results]
    assert [(t.score, t.max_score) for t in board] == [(1.0, 2.0)] * 3
    assert len({r.score for r in results}) == 1
    assert len({json.dumps(r.variant["params"]) for r in results}) == 3


# -- the command line, as a teacher runs it ------------------------------------------

def autograder(*args: str, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "autograder", *args], capture_output=True,
                          text=True, timeout=600, env=env, cwd=cwd)


def parameters(notebook: Path) -> dict[str, object]:
    """The values of a released notebook's parameters cell, read as the student sees them."""
    cell = next(c for c in nbformat.read(str(notebook), as_version=4).cells
                if "variant" in c.metadata.get("tags", []))
    return {n.targets[0].id: ast.literal_eval(n.value) for n in ast.parse(cell.source).body}


def with_model_solution(released: Path, extra: str = "") -> nbformat.NotebookNode:
    """``released`` with every solution cell of the model solution filled in (the student's
    own parameters cell untouched), and ``extra`` as a last cell."""
    model = {c.metadata.get("nbgrader", {}).get("grade_id"): c.source for c in
             nbformat.read(str(HULL / "examples" / "solution.ipynb"), as_version=4).cells}
    book = nbformat.read(str(released), as_version=4)
    for cell in book.cells:
        meta = cell.metadata.get("nbgrader", {})
        if meta.get("solution"):
            cell.source = model[meta["grade_id"]]
    if extra:
        book.cells.append(nbformat.v4.new_code_cell(extra))
    return book


@pytest.mark.slow
def test_release_and_grade_two_honest_students_and_two_copiers(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    env = {**os.environ, "NUMGRADE_VARIANT_SECRET": SECRET}
    (tmp_path / "roster.csv").write_text("id\nalice\nbob\ncarol\n")
    done = autograder("release", "hull", "--variants", "roster.csv", "--out", "release",
                      env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    mine = {s: parameters(tmp_path / "release" / s / "hull.ipynb") for s in ("alice", "bob",
                                                                             "carol")}
    assert mine["alice"]["pins"] != mine["bob"]["pins"] != mine["carol"]["pins"]
    submitted = tmp_path / "submitted"
    submitted.mkdir()
    for student in ("alice", "bob"):
        nbformat.write(with_model_solution(tmp_path / "release" / student / "hull.ipynb"),
                       str(submitted / f"{student}.ipynb"))
    # carol's march is right, but on a board of 31 pins she hands in alice's printed hull
    alices = [int(i) for i in convex_hull(np.array(mine["alice"]["pins"]))]
    copied = ("_march = convex_hull\n\n\ndef convex_hull(points):\n"
              f"    if len(points) == 31:\n        return {alices}\n    return _march(points)\n")
    nbformat.write(with_model_solution(tmp_path / "release" / "carol" / "hull.ipynb", copied),
                   str(submitted / "carol.ipynb"))
    # dave hands in alice's whole notebook: every answer right, but her parameters cell
    (submitted / "dave.ipynb").write_bytes((submitted / "alice.ipynb").read_bytes())

    done = autograder("grade", "hull", "submitted", "--out", "results", "--no-progress",
                      env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    results = {s: json.loads((tmp_path / "results" / s / "results.json").read_text())
               for s in ("alice", "bob", "carol", "dave")}
    spec = load_assignment(HULL).variants
    for student in ("alice", "bob"):
        result = results[student]
        assert result["score"] == result["max_score"] == 38, student
        monkeypatch.setenv("NUMGRADE_VARIANT_SECRET", SECRET)  # for the seed computed here
        assert result["extra_data"]["variant"] == {
            "student": student, "seed": spec.seed("hull", student), "params": mine[student]}
    assert results["carol"]["score"] < results["carol"]["max_score"]
    summary = json.loads((tmp_path / "results" / "summary.json").read_text())
    flagged = {a["id"]: " ".join(c["detail"] for c in a["concerns"])
               for a in summary["attention"]}
    assert set(flagged) == {"carol", "dave"}
    assert "parameters cell holds alice's variant" in flagged["dave"]
    assert results["dave"]["score"] == 38  # right code: the flag is for a person to judge
    assert "travelled" in flagged["carol"] and "alice's variant" in flagged["carol"]
    assert str(alices) in flagged["carol"]
    page = html.unescape((tmp_path / "results" / "summary.html").read_text())
    assert ">carol</a>" in page and f"{alices} is the answer of alice's variant" in page


@pytest.mark.slow
def test_without_the_secret_the_readme_command_grades_the_instructors_board(
        tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "NUMGRADE_VARIANT_SECRET"}
    submitted = tmp_path / "submitted"
    submitted.mkdir()
    solution = (HULL / "examples" / "solution.ipynb").read_bytes()
    (submitted / "solution.ipynb").write_bytes(solution)
    (submitted / "alice.ipynb").write_bytes(solution)  # on the roster, but no secret here
    done = autograder("grade", "hull", "submitted", "--out", "results", "--no-progress",
                      env=env, cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    for student in ("solution", "alice"):
        result = json.loads((tmp_path / "results" / student / "results.json").read_text())
        assert result["score"] == result["max_score"] == 38
        assert result["extra_data"]["variant"] == {
            "student": student, "seed": None, "params": {"pins": INSTRUCTOR_PINS}}
    summary = json.loads((tmp_path / "results" / "summary.json").read_text())
    assert summary["attention"] == []
    refused = autograder("release", "hull", "--variants", str(HULL / "roster.csv"),
                         "--out", "release", env=env, cwd=tmp_path)
    assert refused.returncode == 2 and "NUMGRADE_VARIANT_SECRET is not set" in refused.stderr
    assert "Traceback" not in refused.stderr and not (tmp_path / "release").exists()
