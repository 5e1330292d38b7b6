"""Unseen data that do not depend on luck (issue 8.4): one score per example, whatever the seed.

Unseen inputs are drawn from the assignment and the student's id. Every shipped
example is graded under several student ids (so several sets of unseen data)
by one in-process :class:`~autograder.grading.Grader` per assignment, and must
get the same score under every id: pass lines sit away from where plausible
submissions fall (a uniform-parameter car fails the chord-length test clearly,
a correct car passes clearly), whatever the data.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from autograder.assignment import load_assignment
from autograder.grading import Grader, GradingOptions, submission_seed

ROOT = Path(__file__).resolve().parents[2]
ASSIGNMENTS = sorted(p.parent.name for p in (ROOT / "assignments").glob("*/assignment.toml"))
#: student ids: each gives other unseen data
IDS = [f"student-{k}" for k in range(4)]

pytestmark = pytest.mark.slow


def test_the_ids_give_different_seeds() -> None:
    """Otherwise the test below would grade the same data eight times."""
    assignment = load_assignment("hull")
    assert len({submission_seed(assignment, i) for i in IDS}) == len(IDS)


@pytest.mark.parametrize("name", ASSIGNMENTS)
def test_each_example_gets_one_score_under_every_seed(name: str) -> None:
    assignment = load_assignment(name)
    examples = sorted((ROOT / "assignments" / name / "examples").glob("*.ipynb"))
    spread = []
    with Grader(assignment, GradingOptions()) as grader:
        for path in examples:
            scores: dict[float, list[str]] = {}
            details: dict[str, dict[str, float]] = {}
            for sub_id in IDS:
                result = grader.grade(path, id=sub_id)
                assert result.outcome != "error", f"{name}/{path.stem} ({sub_id}): {result.output}"
                scores.setdefault(round(result.score, 6), []).append(sub_id)
                details[sub_id] = {t.name: t.score for t in result.tests}
            if len(scores) > 1:
                first = details[IDS[0]]
                differ = sorted({check for d in details.values() for check, s in d.items()
                                 if s != first.get(check)})
                spread.append(f"{path.stem}: scores {sorted(scores)} (checks that differ: "
                              f"{', '.join(differ)})")
    assert not spread, f"{name}: a score depends on the unseen data:\n" + "\n".join(spread)
