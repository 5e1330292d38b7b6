"""Every shipped assignment, end to end: release it, then grade its sample submissions.

Each ``assignments/<name>/examples/expected.toml`` says what each sample must
score (a band of the total, as a fraction) and which words its feedback must
contain. The released template (made by ``autograder release``) must score zero
without a grader error, and the solution full marks. The release and the batch
are the session's (``examples_batch`` in conftest.py, which test_unseen_stability.py
reads too): every example is graded under several student folders, and each copy
must be in its band.
"""

from __future__ import annotations

import json
import tomllib
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.support.examples import EXAMPLE_STUDENTS, ExamplesBatch

ROOT = Path(__file__).resolve().parents[2]
ASSIGNMENTS = sorted(p.parent.name for p in (ROOT / "assignments").glob("*/assignment.toml"))
CASES = [(name, stem) for name in ASSIGNMENTS
         for stem in tomllib.loads((ROOT / "assignments" / name / "examples" / "expected.toml")
                                   .read_text())]

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("name", ASSIGNMENTS)
def test_release_ships_no_solution_or_hidden_check(
        examples_batch: Callable[[str], ExamplesBatch], name: str) -> None:
    release = examples_batch(name).release
    notebook = next(release.glob("*.ipynb")).read_text()
    assert "### BEGIN SOLUTION" not in notebook
    assert not (release / "checks" / "hidden").exists()
    assert list((release / "checks" / "public").glob("test_*.py"))
    for hidden in (ROOT / "assignments" / name / "checks" / "hidden").glob("*.py"):
        assert not list(release.rglob(hidden.name))


@pytest.mark.parametrize(("name", "stem"), CASES, ids=[f"{n}-{s}" for n, s in CASES])
def test_example_scores_in_its_band(examples_batch: Callable[[str], ExamplesBatch], name: str,
                                    stem: str) -> None:
    """Every copy of the example (one per student folder of the session's batch, so under
    several seeds), or the released template, in its band."""
    expected = tomllib.loads((ROOT / "assignments" / name / "examples" / "expected.toml")
                             .read_text())[stem]
    batch = examples_batch(name)
    results = [batch.template()] if stem == "template" else batch.copies(stem)
    assert len(results) == (1 if stem == "template" else len(EXAMPLE_STUDENTS))
    for result in results:
        label = f"{name}/{result['extra_data']['id']}"
        assert result["extra_data"]["outcome"] != "error", result["output"]
        fraction = result["score"] / result["max_score"]
        failed = "\n".join(f"  {t['name']}: {t['output'][:200]}" for t in result["tests"]
                           if t["status"] != "passed")
        assert expected["min"] - 1e-9 <= fraction <= expected["max"] + 1e-9, (
            f"{label} scored {fraction:.3f}, expected [{expected['min']}, {expected['max']}]"
            f"\n{result['output']}\n{failed}")
        text = json.dumps(result)
        for word in expected.get("contains", []):
            assert word in text, f"{label}: the feedback never says {word!r}"


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
