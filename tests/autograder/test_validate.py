"""`autograder validate`: leaks found file by file, bands read and enforced."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from autograder.authoring.release import release
from autograder.authoring.scaffold import new_assignment
from autograder.authoring.validate import (
    ExampleCheck,
    ValidationRun,
    find_leaks,
    format_report,
    validate,
)
from autograder.engine.assignment import load_assignment


@pytest.fixture
def quad(tmp_path: Path) -> Path:
    return new_assignment("quad", out=tmp_path / "src")


def test_a_clean_release_has_no_leaks(quad: Path, tmp_path: Path) -> None:
    found = load_assignment(quad)
    release(found, tmp_path / "out")
    assert find_leaks(found, tmp_path / "out") == []


def test_a_solution_line_in_a_public_file_is_a_leak(quad: Path, tmp_path: Path) -> None:
    found = load_assignment(quad)
    release(found, tmp_path / "out")
    helper = tmp_path / "out" / "checks" / "public" / "quad_helper.py"
    helper.write_text("    return float(h * (y.sum() - 0.5 * (y[0] + y[-1])))\n")
    leaks = find_leaks(found, tmp_path / "out")
    assert len(leaks) == 1 and "solution or hidden-check line" in leaks[0]
    assert "quad_helper.py" in leaks[0]


def test_a_line_pasted_into_a_sentence_is_a_leak(quad: Path, tmp_path: Path) -> None:
    found = load_assignment(quad)
    release(found, tmp_path / "out")
    notebook = tmp_path / "out" / "quad.ipynb"
    notebook.write_text(notebook.read_text().replace(
        "Write `trapezoid(f, a, b, n)`.", "Hint: y = np.asarray(f(x), dtype=float) works."))
    leaks = find_leaks(found, tmp_path / "out")
    assert leaks == ["quad.ipynb contains a solution or hidden-check line: "
                     "'y = np.asarray(f(x), dtype=float)'"]


def test_a_hidden_check_copied_or_quoted_is_a_leak(quad: Path, tmp_path: Path) -> None:
    found = load_assignment(quad)
    release(found, tmp_path / "out")
    hidden = quad / "checks" / "hidden" / "test_quad_hidden.py"
    shutil.copyfile(hidden, tmp_path / "out" / "data" / "notes.txt")
    (tmp_path / "out" / "data" / "more.txt").write_text(
        "got = student.trapezoid(f, -0.5, 1.5, 40)\n### BEGIN HIDDEN TESTS\n")
    leaks = find_leaks(found, tmp_path / "out")
    assert any("notes.txt is a copy of the hidden check" in leak for leak in leaks)
    assert any("more.txt contains 'BEGIN HIDDEN TESTS'" in leak for leak in leaks)
    assert any("more.txt contains a solution or hidden-check line" in leak for leak in leaks)


def test_a_leaking_notebook_fails_validation_before_grading(quad: Path, tmp_path: Path) -> None:
    notebook = quad / "quad.ipynb"
    text = notebook.read_text()
    line = "got = student.trapezoid(f, -0.5, 1.5, 40)"
    notebook.write_text(text.replace("Write `trapezoid(f, a, b, n)`.", f"\\n{line}\\n"))
    report = validate(load_assignment(quad), work=tmp_path / "work")
    assert not report.ok and report.examples == ()
    assert "Refusing to release" in report.leaks[0]
    assert "NOT valid" in format_report(report)


def test_bad_bands_are_reported(quad: Path) -> None:
    from autograder.authoring.validate import _read_bands

    (quad / "examples" / "expected.toml").write_text(
        "[solution]\nmin = 1\nmax = 0.5\n[other]\nmin = 0\nmax = 1\ncontains = 'x'\n")
    bands, problems = _read_bands(load_assignment(quad))
    assert bands == {}
    assert any("[solution] needs min and max" in p for p in problems)
    assert any("[other] contains must be a list" in p for p in problems)


def test_the_table_marks_rows_outside_their_band() -> None:
    report = ValidationRun("quad", (
        ExampleCheck("solution", 5, 5, 1.0, 1.0, "graded"),
        ExampleCheck("wrong-x", 2, 5, 0.0, 0.2, "graded", ("scored 0.400, outside [0, 0.2]",)),
    ))
    text = format_report(report)
    assert not report.ok
    assert "  solution" in text and "ok" in text.splitlines()[3]
    assert "FAIL" in text.splitlines()[4] and "outside [0, 0.2]" in text
    assert report.to_dict()["examples"][1]["ok"] is False


@pytest.mark.slow
def test_a_score_outside_its_band_fails_the_cli(quad: Path, tmp_path: Path) -> None:
    expected = quad / "examples" / "expected.toml"
    expected.write_text(expected.read_text().replace(
        "[wrong-left-endpoints]   # a Riemann sum: wrong values on both checks\nmin = 0\nmax = 0",
        "[wrong-left-endpoints]\nmin = 0.5\nmax = 1"))
    (quad / "examples" / "unbanded.ipynb").write_bytes((quad / "quad.ipynb").read_bytes())
    proc = subprocess.run([sys.executable, "-m", "autograder", "validate", str(quad),
                           "--jobs", "2"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    rows = {line.split()[0]: line.split()[-1] for line in proc.stdout.splitlines()
            if line.startswith("  ") and len(line.split()) >= 5}
    assert rows["solution"] == "ok" and rows["template"] == "ok"
    assert rows["wrong-left-endpoints"] == "FAIL" and rows["unbanded"] == "FAIL"
    assert "outside [0.5, 1]" in proc.stdout and "no band in examples/expected.toml" in proc.stdout
