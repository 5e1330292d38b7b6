"""The grading plugin on its own: verdicts, points, partial credit, messages (no worker)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from autograder.engine.checkrun import CheckSuite
from autograder.engine.plugin import CheckContext
from autograder.errors import CallTimeout, StudentException

CHECKS = '''
import pytest

@pytest.mark.points(2)
def test_passes(student):
    assert student.double(2) == 4, "double(2) should be 4"

@pytest.mark.points(3)
def test_partial(student, credit):
    credit.partial(0.5, "right idea, wrong orientation")

def test_wrong(student):
    assert student.double(3) == 7, "expected 7 for double(3)"

def test_secret_source_not_shown(student):
    assert student.double(1) == 99

def test_raises(student):
    student.boom()

def test_times_out(student):
    student.slow()

def test_missing(student):
    student.nowhere()

def test_forbidden(student):
    student.cheat()

def test_check_bug(student):
    return {}["hidden-dataset-key"]

@pytest.mark.parametrize("n", [1, 2])
def test_seeded(student, rng, n):
    assert 0 <= rng.integers(10) < 10

@pytest.mark.points(0.5)
@pytest.mark.parametrize("name", ["tiny", "huge"])
def test_datasets(student, name):
    assert name == "tiny", f"failed on {name}"
'''


class FakeTarget:
    """Stands in for a worker: plain Python functions, the same error types."""

    def call(self, name: str, args: Any, kwargs: dict[str, Any], *, timeout: float,
             figures: bool = False) -> tuple[Any, list[Any]]:
        if name == "double":
            return args[0] * 2, []
        if name == "boom":
            raise StudentException("boom raised ValueError: bad", traceback="Traceback: cell 3")
        if name == "slow":
            raise CallTimeout("slow() did not return within 1 s")
        raise AssertionError(f"unexpected call {name}")

    def figures(self, *, timeout: float) -> list[Any]:
        return []


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    tmp_path = tmp_path_factory.mktemp("plugin")
    hidden = tmp_path / "checks" / "hidden"
    hidden.mkdir(parents=True)
    (hidden / "test_demo.py").write_text(CHECKS)
    context = CheckContext(
        target=FakeTarget(), functions=("double", "boom", "slow", "cheat"),
        forbidden={"cheat": "`cheat` uses scipy.spatial, which is not allowed."},
        call_timeout=1.0, seed=42, hidden_root=hidden)
    session = CheckSuite([hidden / "test_demo.py"], tmp_path, name="demo", context=context)
    try:
        run = session.run(context)
    finally:
        session.close()
    return {r.name: r for r in run.results}


def test_passing_check_gets_its_points(results: dict[str, Any]) -> None:
    r = results["passes"]
    assert (r.score, r.max_score, r.status) == (2.0, 2.0, "passed")


def test_partial_credit(results: dict[str, Any]) -> None:
    r = results["partial"]
    assert (r.score, r.max_score, r.status, r.kind) == (1.5, 3.0, "failed", "partial")
    assert r.output == "right idea, wrong orientation"


def test_wrong_answer_message(results: dict[str, Any]) -> None:
    assert results["wrong"].output == "expected 7 for double(3)"
    assert results["wrong"].score == 0


def test_bare_assert_never_shows_the_check_source(results: dict[str, Any]) -> None:
    out = results["secret_source_not_shown"].output
    assert "99" not in out and "student.double" not in out
    assert out == "This check failed."


def test_student_exception_carries_traceback(results: dict[str, Any]) -> None:
    r = results["raises"]
    assert r.kind == "exception" and "ValueError" in r.output and "cell 3" in r.output


def test_timeout_missing_forbidden(results: dict[str, Any]) -> None:
    assert results["times_out"].kind == "timeout"
    assert results["missing"].kind == "missing" and "does not define `nowhere`" in results["missing"].output
    assert results["forbidden"].kind == "forbidden" and "scipy.spatial" in results["forbidden"].output


def test_bug_in_hidden_check_shows_no_detail(results: dict[str, Any]) -> None:
    r = results["check_bug"]
    assert r.kind == "check-error" and "hidden-dataset-key" not in r.output


def test_parametrised_items_are_named_by_dataset(results: dict[str, Any]) -> None:
    assert results["datasets[tiny]"].score == 0.5
    assert results["datasets[huge]"].output == "failed on huge"
    assert results["datasets[huge]"].dataset == "huge"
    assert results["seeded[1]"].hidden


def test_total_points(results: dict[str, Any]) -> None:
    assert sum(r.max_score for r in results.values()) == pytest.approx(2 + 3 + 7 + 2 + 1)
