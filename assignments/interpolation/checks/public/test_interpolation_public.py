"""Public checks for the interpolation assignment: small cases you can verify by hand.

Run them with ``autograder check interpolation.ipynb``. The graded checks use
more functions, other node sets, larger degrees and sizes you have not seen,
and look closely at what happens at and right next to the nodes.

Expected interpolants here come from ``numpy.polynomial`` least squares with
as many coefficients as nodes (an exact fit, accurate to about 1e-13 for these
small degrees), so this file gives away no barycentric formula. In your own
code ``numpy.polynomial`` is not allowed.
"""

from __future__ import annotations

import math

from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import ArrayLike

import interp_feedback as fb  # checks/public/interp_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Feedback, Student, over_datasets


def cheb2(n: int) -> np.ndarray:
    """Chebyshev points of the second kind, ascending."""
    return -np.cos(np.pi * np.arange(n + 1) / n)


def cheb1(n: int) -> np.ndarray:
    """Chebyshev points of the first kind (a common mix-up), ascending."""
    return -np.cos((2 * np.arange(n + 1) + 1) * np.pi / (2 * n + 2))


def fitted(nodes: ArrayLike,
           f: Callable[[ArrayLike], np.ndarray] = fb.runge) -> np.polynomial.Polynomial:
    """The polynomial through (nodes, f(nodes)), by an exact least-squares fit."""
    nodes = np.asarray(nodes, dtype=float)
    return np.polynomial.Polynomial.fit(nodes, f(nodes), deg=nodes.size - 1)


#: name -> (function, n, expected nodes, known wrong answers)
NODES = {
    "equispaced-4": ("equispaced_nodes", 4, [-1.0, -0.5, 0.0, 0.5, 1.0], {}),
    "chebyshev-4": ("chebyshev_nodes", 4, [-1.0, -math.sqrt(0.5), 0.0, math.sqrt(0.5), 1.0],
                    {fb.FIRST_KIND: cheb1(4)}),
    "chebyshev-7": ("chebyshev_nodes", 7, cheb2(7), {fb.FIRST_KIND: cheb1(7)}),
}

def _equispaced_ratios(n: int) -> np.ndarray:
    """(-1)^j C(n, j) / C(n, n // 2), each correctly rounded (exact integers divided)."""
    top = math.comb(n, n // 2)
    return np.array([(-1) ** j * (math.comb(n, j) / top) for j in range(n + 1)])


#: name -> (function, n, expected weights at any scale, overflow hint, known wrong answers)
WEIGHTS = {
    "equispaced-4": ("equispaced_weights", 4, [1.0, -4.0, 6.0, -4.0, 1.0], fb.EQUISPACED_HINT,
                     {fb.CHEBYSHEV_FOR_EQUISPACED: fb.alternating(4)}),
    "chebyshev-4": ("chebyshev_weights", 4, [0.5, -1.0, 1.0, -1.0, 0.5], fb.CHEBYSHEV_HINT,
                    {fb.NOT_HALVED: fb.alternating(4)}),
    "equispaced-1100": ("equispaced_weights", 1100, _equispaced_ratios(1100),
                        fb.EQUISPACED_HINT, {}),
}


@over_datasets(NODES, "case", points=1)
def test_nodes_small(student: Student, credit: Credit, case: str) -> None:
    name, n, expected, known = NODES[case]
    got = getattr(student, name)(n)
    fb.judge_nodes(got, np.asarray(expected), call=f"{name}({n})",
                   what=name.split("_")[0].replace("chebyshev", "Chebyshev") + " nodes",
                   credit=credit, known=known)


@over_datasets(WEIGHTS, "case", points=1)
def test_weights_small(student: Student, case: str) -> None:
    name, n, expected, hint, known = WEIGHTS[case]
    call = f"{name}({n})"
    got = fb.call_weights(getattr(student, name), n, call=call, hint=hint)
    fb.judge_weights(got, np.asarray(expected), call=call, n=n, hint=hint, known=known)


@pytest.mark.points(1)
def test_interp_x_squared(student: Student, credit: Credit) -> None:
    """Three nodes reproduce x^2 exactly; weights 1/2, -1, 1/2."""
    x, w = np.array([-1.0, 0.0, 1.0]), np.array([0.5, -1.0, 0.5])
    t = np.array([-0.5, 0.25, 0.5, 0.9])
    got = student.lagrange_interp(x**2, x, w, t)
    fb.judge_values(got, t**2, t=t, nodes=x, tol=1e-14, credit=credit,
                    call="lagrange_interp(x**2, [-1, 0, 1], [0.5, -1, 0.5], t)")


@pytest.mark.points(1)
def test_interp_runge_chebyshev_10(student: Student, credit: Credit) -> None:
    """Runge's function in 11 Chebyshev points, on a grid that includes the end nodes."""
    x = cheb2(10)
    w = np.where(np.arange(11) % 2 == 0, 1.0, -1.0)
    w[[0, -1]] *= 0.5
    t = np.linspace(-1.0, 1.0, 201)
    got = student.lagrange_interp(fb.runge(x), x, w, t)
    # tolerance: the fit is accurate to about 1e-13, the barycentric formula to 1e-15
    fb.judge_values(got, fitted(x)(t), t=t, nodes=x, tol=1e-11, credit=credit,
                    call="lagrange_interp(f(x), x, w, t) with 11 Chebyshev points")


@pytest.mark.points(1)
def test_interp_scalar(student: Student, credit: Credit) -> None:
    x, w = np.array([-1.0, 0.0, 1.0]), np.array([0.5, -1.0, 0.5])
    call = "lagrange_interp(x**2, [-1, 0, 1], [0.5, -1, 0.5], 0.3)"
    value = fb.judge_scalar(student.lagrange_interp(x**2, x, w, 0.3), call=call, credit=credit)
    fb.judge_values(value, np.float64(0.09), t=np.float64(0.3), nodes=x, tol=1e-15,
                    credit=credit, call=call)


@pytest.mark.points(1)
def test_interp_exact_at_nodes(student: Student) -> None:
    """At the nodes the answer is the data itself, bit for bit (the lecture's weights)."""
    x = np.linspace(-1.0, 1.0, 5)
    # data that are not Runge's function: the answer must come from fvals
    f, w = np.array([0.5, -1.25, 2.0, 0.75, -0.5]), np.array([1.0, -4.0, 6.0, -4.0, 1.0])
    got = student.lagrange_interp(f, x, w, x)
    fb.judge_exact(got, f, x, np.arange(5), call="lagrange_interp(f, x, w, t=x)")
    for j in (1, 3):
        got = student.lagrange_interp(f, x, w, float(x[j]))
        fb.judge_exact(got, f, x, np.array(j),
                       call=f"lagrange_interp(f, x, w, t={x[j]})")


#: the nodes of each family, by degree
FAMILIES = {"equispaced": lambda m: np.linspace(-1.0, 1.0, m + 1), "Chebyshev": cheb2}


@pytest.mark.points(2)
def test_plot_runge_10(student: Student, credit: Credit, feedback: Feedback) -> None:
    fb.grade_runge_plot(student, feedback, credit, 10,
                        lambda family, m: fitted(FAMILIES[family](m)))
