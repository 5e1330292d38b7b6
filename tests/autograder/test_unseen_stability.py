"""Unseen data that do not depend on luck (issue 8.4): one score per example, whatever the seed.

Unseen inputs are drawn from the assignment and the student's id. Every shipped
example is graded under several student ids (so several sets of unseen data) in
one batch per assignment, through the real CLI with two jobs as an instructor
grades (the id comes from the file's place: ``<student>/<example>.ipynb``; the
session's batch, ``examples_batch`` in conftest.py, which test_assignments.py reads
too), and must get the same score under every id: pass lines sit away from where plausible
submissions fall (a uniform-parameter car fails the chord-length test clearly, a
correct car passes clearly), whatever the data.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import submission_seed
from tests.support.examples import EXAMPLE_STUDENTS, ExamplesBatch

ROOT = Path(__file__).resolve().parents[2]
ASSIGNMENTS = sorted(p.parent.name for p in (ROOT / "assignments").glob("*/assignment.toml"))

pytestmark = pytest.mark.slow


def test_the_students_give_different_seeds() -> None:
    """Otherwise the test below would grade the same data several times."""
    assignment = load_assignment("hull")
    ids = [f"{e}+{s}" for s in EXAMPLE_STUDENTS for e in ("solution", "wrong-clockwise")]
    assert len({submission_seed(assignment, i) for i in ids}) == len(ids)


@pytest.mark.parametrize("name", ASSIGNMENTS)
def test_each_example_gets_one_score_under_every_seed(
        examples_batch: Callable[[str], ExamplesBatch], name: str) -> None:
    batch = examples_batch(name)  # every example under each of EXAMPLE_STUDENTS, --jobs 2
    results = batch.results()
    assert len(results) == len(EXAMPLE_STUDENTS) * len(batch.examples)
    assert len({r["extra_data"]["seed"] for r in results}) == len(results), \
        "every copy has its own data"
    by_example: dict[str, list[tuple[str, float, dict[str, float]]]] = {}
    for result in results:
        extra = result["extra_data"]
        assert extra["outcome"] != "error", f"{name}/{extra['id']}: {result['output']}"
        by_example.setdefault(Path(extra["source"]).stem, []).append(
            (extra["id"], round(result["score"], 6), {t["name"]: t["score"] for t in result["tests"]}))
    spread = []
    for stem, graded in sorted(by_example.items()):
        assert len(graded) == len(EXAMPLE_STUDENTS)
        if len({score for _, score, _ in graded}) > 1:
            first = graded[0][2]
            differ = sorted({check for _, _, d in graded for check, s in d.items()
                             if s != first.get(check)})
            spread.append(f"{stem}: scores {sorted(score for _, score, _ in graded)} "
                          f"(checks that differ: {', '.join(differ)})")
    assert not spread, f"{name}: a score depends on the unseen data:\n" + "\n".join(spread)
