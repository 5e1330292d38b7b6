"""`autograder new`: the folder it writes loads, releases and (end to end) validates."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import nbformat
import pytest

from autograder.authoring.release import release
from autograder.authoring.scaffold import new_assignment
from autograder.engine.assignment import load_assignment
from autograder.errors import UsageError


def test_new_writes_a_complete_assignment_folder(tmp_path: Path) -> None:
    root = new_assignment("quad", out=tmp_path)
    assert root == tmp_path / "quad"
    found = load_assignment(root)
    assert found.name == "quad" and found.notebook == root.resolve() / "quad.ipynb"
    assert [p.name for p in found.public_checks] == ["test_quad_public.py"]
    assert [p.name for p in found.hidden_checks] == ["test_quad_hidden.py"]
    assert [p.name for p in found.data_files] == ["samples.csv"]
    bands = tomllib.loads((root / "examples" / "expected.toml").read_text())
    examples = {p.stem for p in (root / "examples").glob("*.ipynb")}
    assert set(bands) == examples | {"template"}
    nb = nbformat.read(str(found.notebook), as_version=4)
    nbformat.validate(nb)
    solutions = [c for c in nb.cells if c.metadata.get("nbgrader", {}).get("solution")]
    assert len(solutions) == 1 and "### BEGIN SOLUTION" in solutions[0].source


def test_the_new_folder_releases_without_its_solution(tmp_path: Path) -> None:
    root = new_assignment("quad", out=tmp_path / "src")
    notebook = release(load_assignment(root), tmp_path / "release")
    text = notebook.read_text()
    assert "BEGIN SOLUTION" not in text and "np.linspace(a, b, n + 1)" not in text
    assert (tmp_path / "release" / "data" / "samples.csv").is_file()
    assert not (tmp_path / "release" / "checks" / "hidden").exists()


@pytest.mark.parametrize("name", ["", "Quad", "1quad", "quad-2", "../quad", "a" * 41])
def test_bad_names_are_refused_with_the_rule(tmp_path: Path, name: str) -> None:
    with pytest.raises(UsageError, match="lower-case letters, digits and underscores"):
        new_assignment(name, out=tmp_path)


def test_new_never_overwrites(tmp_path: Path) -> None:
    new_assignment("quad", out=tmp_path)
    with pytest.raises(UsageError, match="already exists"):
        new_assignment("quad", out=tmp_path)


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "autograder", *args], capture_output=True,
                          text=True, timeout=900, cwd=cwd)


@pytest.mark.slow
def test_new_then_validate_passes_through_the_cli(tmp_path: Path) -> None:
    made = run("new", "quad", "--out", str(tmp_path / "course"), cwd=tmp_path)
    assert made.returncode == 0, made.stderr
    assert "autograder validate" in made.stdout
    checked = run("validate", str(tmp_path / "course" / "quad"), "--jobs", "2", cwd=tmp_path)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    rows = {line.split()[0]: line.split()[-1] for line in checked.stdout.splitlines()
            if line.startswith("  ") and len(line.split()) >= 5}
    assert rows == {"example": "result", "solution": "ok", "template": "ok",
                    "wrong-left-endpoints": "ok"}
    assert "every example is in its band and nothing leaked" in checked.stdout
