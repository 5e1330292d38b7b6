"""Public checks for the approximation assignment: small cases you can verify by hand.

Run them with ``autograder check approximation.ipynb``. The graded checks pass
your functions other functions `f` that you have not seen, with other degrees
and points, and count where your code evaluates them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import approximation_feedback as fb  # checks/public/: on sys.path while checks run
from autograder.engine.callbacks import traced
from autograder.checks import (Credit, Student, expect_array, expect_close, expect_number,
                               over_datasets)

NODES = {
    "chebyshev-4": (4, "chebyshev", [-1.0, -math.sqrt(0.5), 0.0, math.sqrt(0.5), 1.0]),
    "equispaced-4": (4, "equispaced", [-1.0, -0.5, 0.0, 0.5, 1.0]),
}


@over_datasets(NODES, points=1)
def test_nodes(student: Student, name: str) -> None:
    n, kind, expected = NODES[name]
    expect_close(student.interpolation_nodes(n, kind), expected, rtol=0, atol=1e-14,
                 name=f"interpolation_nodes({n}, {kind!r})")


@pytest.mark.points(2)
def test_interpolate_exp_on_the_grid(student: Student, credit: Credit) -> None:
    f = traced(lambda x: np.exp(x))
    got = student.interpolate(f, 10)
    # SciPy's interpolant in the same nodes: rounding only (Chebyshev points are well conditioned)
    fb.expect_values(student, f, got, fb.scipy_interpolant(f, 10, "chebyshev", fb.GRID), n=10,
                     kind="chebyshev", t=fb.GRID, rtol=1e-12, atol=1e-13, credit=credit,
                     name="interpolate(exp, 10)")
    fb.expect_sampled_at_nodes(student, f, 10, "chebyshev", what="interpolate(exp, 10)")


@pytest.mark.points(2)
def test_make_interpolant_reproduces_a_cubic(student: Student) -> None:
    f = traced(lambda x: x**3 - x)
    p = student.make_interpolant(f, 3)
    assert callable(p), "make_interpolant must return a function p(t)"
    t = np.array([-0.3, 0.25, 0.9])
    expect_close(p(t), t**3 - t, rtol=0, atol=1e-14, name="p(t) for f(x) = x^3 - x, n = 3")
    expect_number(p(0.5), name="p(0.5)", hint="A number t must give a number.")


@pytest.mark.points(1)
def test_convergence_for_runge(student: Student) -> None:
    f = traced(lambda x: 1 / (1 + 25 * x**2))
    ns = [4, 8, 16, 32]
    errors = expect_array(student.convergence(f, ns), shape=(4,), name="convergence(f, ns)")
    expected = np.array([np.max(np.abs(fb.scipy_interpolant(f, n, "chebyshev", fb.GRID)
                                       - f(fb.GRID))) for n in ns])
    # NaN because p is NaN at the nodes is charged once, by the check at the nodes
    errors = fb.nan_from_nodes(student, lambda x: 1 / (1 + 25 * x**2), ns, errors)
    # errors of 1e-1 .. 1e-3: a correct interpolant matches them to many digits
    expect_close(errors, expected, rtol=1e-6, atol=1e-13, name="convergence(f, [4, 8, 16, 32])")
