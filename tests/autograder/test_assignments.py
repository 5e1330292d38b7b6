"""Every shipped assignment, end to end: release it, then grade its sample submissions.

Each ``assignments/<name>/examples/expected.toml`` says what each sample must
score (a band of the total, as a fraction) and which words its feedback must
contain. The released template (made here by ``autograder release``) must
score zero without a grader error, and the solution full marks.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tomllib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ASSIGNMENTS = sorted(p.parent.name for p in (ROOT / "assignments").glob("*/assignment.toml"))
CASES = [(name, stem) for name in ASSIGNMENTS
         for stem in tomllib.loads((ROOT / "assignments" / name / "examples" / "expected.toml")
                                   .read_text())]

pytestmark = pytest.mark.slow


def run(*args: str, timeout: float = 600) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "autograder", *args], capture_output=True,
                          text=True, timeout=timeout)


def release_and_grade(name: str, work: Path) -> Path:
    """Release ``name`` into ``work`` and grade its examples plus the released template."""
    released = run("release", name, "--out", str(work / "release"))
    assert released.returncode == 0, released.stderr
    submissions = work / "submissions"
    shutil.copytree(ROOT / "assignments" / name / "examples", submissions,
                    ignore=shutil.ignore_patterns("*.toml"))
    notebook = next((work / "release").glob("*.ipynb"))
    shutil.copy(notebook, submissions / "template.ipynb")
    proc = run("grade", name, str(submissions), "--out", str(work / "results"),
               "--jobs", "1", "--no-progress")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return work


@pytest.fixture(scope="module")
def graded(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Release each assignment and grade its examples plus the released template.

    Two assignments at a time, each graded on one slot: as many grading processes as
    ``--jobs 2`` one after the other, but one assignment's release (nbgrader, one core)
    and start-up overlap the other's grading, where they used to leave a core idle."""
    works = {name: tmp_path_factory.mktemp(name) for name in ASSIGNMENTS}
    with ThreadPoolExecutor(max_workers=2) as pool:
        done = {name: pool.submit(release_and_grade, name, work) for name, work in works.items()}
        return {name: future.result() for name, future in done.items()}


@pytest.mark.parametrize("name", ASSIGNMENTS)
def test_release_ships_no_solution_or_hidden_check(graded: dict[str, Path], name: str) -> None:
    release = graded[name] / "release"
    notebook = next(release.glob("*.ipynb")).read_text()
    assert "### BEGIN SOLUTION" not in notebook
    assert not (release / "checks" / "hidden").exists()
    assert list((release / "checks" / "public").glob("test_*.py"))
    for hidden in (ROOT / "assignments" / name / "checks" / "hidden").glob("*.py"):
        assert not list(release.rglob(hidden.name))


@pytest.mark.parametrize(("name", "stem"), CASES, ids=[f"{n}-{s}" for n, s in CASES])
def test_example_scores_in_its_band(graded: dict[str, Path], name: str, stem: str) -> None:
    expected = tomllib.loads((ROOT / "assignments" / name / "examples" / "expected.toml")
                             .read_text())[stem]
    result = json.loads((graded[name] / "results" / stem / "results.json").read_text())
    assert result["extra_data"]["outcome"] != "error", result["output"]
    fraction = result["score"] / result["max_score"]
    failed = "\n".join(f"  {t['name']}: {t['output'][:200]}" for t in result["tests"]
                       if t["status"] != "passed")
    assert expected["min"] - 1e-9 <= fraction <= expected["max"] + 1e-9, (
        f"{name}/{stem} scored {fraction:.3f}, expected [{expected['min']}, {expected['max']}]"
        f"\n{result['output']}\n{failed}")
    text = json.dumps(result)
    for word in expected.get("contains", []):
        assert word in text, f"{name}/{stem}: the feedback never says {word!r}"


@pytest.mark.parametrize("name", ASSIGNMENTS)
def test_released_checks_never_import_the_model_solutions(name: str) -> None:
    """`reference` is not part of a student's install: public checks and helpers do without it."""
    import ast

    for path in (ROOT / "assignments" / name / "checks" / "public").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n == "reference" or n.startswith("reference.") for n in names), (
                f"{path.relative_to(ROOT)} imports {names}: use stored answers, SciPy, or logic "
                "written in the checks")
