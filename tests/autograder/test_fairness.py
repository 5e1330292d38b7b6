"""Fair credit in approximation's shared judging (issue 26.3), against the answers that were
treated unfairly: each case was scored wrongly by the helpers before the fix.

The end-to-end counterparts (whole notebooks with their bands) are the examples
in ``assignments/approximation/examples`` (``autograder validate approximation``);
junk of every kind, for every assignment, is in ``test_junk.py``.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import pytest

from autograder.errors import CheckFailure, PartialCredit
from tests.autograder.test_course_checks import helper

fb = helper("approximation", "approximation_feedback")


class Sampled:
    """What a check knows of a traced f after a call: where student code evaluated it."""

    def __init__(self, function: Callable[[np.ndarray], np.ndarray], *calls: np.ndarray) -> None:
        self.function = function
        self.points = np.concatenate([np.ravel(c) for c in calls]) if calls else np.zeros(0)
        self.evaluations = self.points.size
        self.calls = len(calls)

    def __call__(self, x: Any) -> np.ndarray:
        return self.function(np.asarray(x, dtype=float))


class Student:
    def __init__(self, nodes: Callable[[int, str], np.ndarray]) -> None:
        self.interpolation_nodes = nodes


class Credit:
    def partial(self, fraction: float, message: str) -> None:
        raise PartialCredit(fraction, message)


HONEST = Student(lambda n, kind: fb.nodes(n, kind))
IGNORES_KIND = Student(lambda n, kind: fb.nodes(n, "chebyshev"))


def first_kind(n: int) -> np.ndarray:
    return -np.cos((2 * np.arange(n + 1) + 1) * np.pi / (2 * n + 2))


def test_a_wrong_node_set_is_named_and_graded_on_its_own_nodes() -> None:
    n, t = 12, np.linspace(-1, 1, 41)
    x = first_kind(n)
    f = Sampled(np.exp, x)
    from scipy.interpolate import BarycentricInterpolator
    got = BarycentricInterpolator(x, np.exp(x))(t)
    with pytest.raises(PartialCredit) as partial:
        fb.expect_values(HONEST, f, got, fb.scipy_interpolant(f, n, "chebyshev", t), n=n,
                         kind="chebyshev", t=t, atol=1e-14, credit=Credit(), name="interpolate")
    assert partial.value.fraction == fb.WRONG_NODES_CREDIT
    assert "wrong node set" in str(partial.value)
    with pytest.raises(CheckFailure) as failure:
        fb.expect_sampled_at_nodes(HONEST, f, n, "chebyshev", what="interpolate")
    assert "wrong node set" in str(failure.value)
    assert "sample f(x) once" not in str(failure.value)


def test_wrong_values_on_a_wrong_node_set_earn_nothing() -> None:
    n, t = 12, np.linspace(-1, 1, 41)
    f = Sampled(np.exp, first_kind(n))
    with pytest.raises(CheckFailure) as failure:
        fb.expect_values(HONEST, f, np.full(t.shape, 1.5),
                         fb.scipy_interpolant(f, n, "chebyshev", t), n=n, kind="chebyshev",
                         t=t, atol=1e-14, credit=Credit(), name="interpolate")
    assert not isinstance(failure.value, PartialCredit)


@pytest.mark.parametrize("student, advice", [
    (HONEST, "pass the kind on to interpolation_nodes"),
    (IGNORES_KIND, "itself returns the Chebyshev nodes: make it honour `kind`"),
])
def test_the_kind_advice_names_whose_mistake_it_is(student: Student, advice: str) -> None:
    f = Sampled(np.cos, fb.nodes(7, "chebyshev"))
    with pytest.raises(CheckFailure) as failure:
        fb.expect_sampled_at_nodes(student, f, 7, "equispaced", what="interpolate")
    assert advice in str(failure.value)
    other = "itself returns" if advice.startswith("pass") else "pass the kind on"
    assert other not in str(failure.value)


def test_extra_evaluations_cost_one_check_in_proportion() -> None:
    x = fb.nodes(24, "chebyshev")
    once, twice = Sampled(np.sin, x), Sampled(np.sin, x, x)
    with pytest.raises(PartialCredit) as partial:
        fb.cost_share([("interpolate", once, 25), ("make_interpolant", twice, 25),
                       ("convergence", once, 25)], Credit())
    assert partial.value.fraction == pytest.approx(5 / 6)
    fb.cost_share([("interpolate", once, 25)], Credit())  # no extra: nothing charged
    # and sampling by the rules no longer takes half of a check by itself
    fb.expect_sampled_at_nodes(HONEST, twice, 24, "chebyshev", what="interpolate")


def test_nan_at_a_node_is_left_to_the_check_at_the_nodes() -> None:
    n, t = 10, np.array([-1.0, 0.123, 1.0])
    expected = np.array([2.0, 3.0, 4.0])
    got = np.array([np.nan, 3.0, np.nan])
    assert np.array_equal(fb.without_nan_at_nodes(got, expected, t, n, "chebyshev"), expected)
    off_node = np.array([2.0, np.nan, 4.0])  # NaN away from a node is the value check's
    assert np.isnan(fb.without_nan_at_nodes(off_node, expected, t, n, "chebyshev")[1])
    assert "LagrangeInterp1D" in fb.NODE_REASON
