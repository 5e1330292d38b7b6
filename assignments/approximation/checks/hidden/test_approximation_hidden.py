"""Hidden checks for the approximation assignment: functions the student has never seen.

Each check passes the student's code a function wrapped in ``traced`` (its code
stays in the grader; the student's code calls it across the boundary), then
compares the values with the ``reference`` package and SciPy and reads where
the function was evaluated.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.interpolate import BarycentricInterpolator

import approximation_feedback as fb  # checks/public/: on sys.path while checks run
from autograder.engine.callbacks import traced
from autograder.checks import (
    CheckFailure,
    Credit,
    Dataset,
    Student,
    expect_array,
    expect_close,
    expect_number,
    over_datasets,
    show_number,
)
from reference import barycentric_interpolate, chebyshev_nodes, equispaced_nodes

Case = tuple[Callable[[np.ndarray], np.ndarray], int, str]

CHEBYSHEV_TOL = ("Chebyshev interpolation is forward stable (Higham 2004): a correct "
                 "barycentric formula lands within a few ulps of the reference times the "
                 "Lebesgue constant (< 4 here); wrong nodes or weights miss by 1e-3 or more")
EQUISPACED_TOL = ("equispaced nodes of degree <= 12 have a Lebesgue constant below 100, so "
                  "rounding stays below 1e-12; Chebyshev nodes instead would miss by 1e-4 or more")

#: unseen functions (never shown to students), their degree and node kind
FUNCTIONS: dict[str, Dataset[Case]] = {
    "unseen-tanh-24": Dataset(lambda rng: (lambda x: np.tanh(4 * (x - 0.2)), 24, "chebyshev"),
                              points=2, tolerance=1e-12, reason=CHEBYSHEV_TOL),
    "unseen-abs-cubed-31": Dataset(lambda rng: (lambda x: np.abs(x - 0.1) ** 3, 31, "chebyshev"),
                                   points=2, tolerance=1e-12, reason=CHEBYSHEV_TOL),
    "unseen-closure-40": Dataset(lambda rng: (_wave(rng.uniform(5.0, 9.0)), 40, "chebyshev"),
                                 points=2, tolerance=1e-12, reason=CHEBYSHEV_TOL),
    "unseen-equispaced-cos-12": Dataset(
        lambda rng: (lambda x: np.cos(3 * x + 0.5), 12, "equispaced"),
        points=2, tolerance=1e-12, reason=EQUISPACED_TOL),
    "unseen-equispaced-quintic-7": Dataset(
        lambda rng: (lambda x: x**5 - 2 * x**2 + 0.25, 7, "equispaced"),
        points=1, tolerance=1e-12, reason="a quintic through 8 nodes is reproduced exactly, "
                                          "up to rounding"),
}


def _wave(k: float) -> Callable[[np.ndarray], np.ndarray]:
    """A closure with a frequency drawn per submission: no two students see the same f."""
    return lambda x: np.sin(k * x) * np.exp(-x)


def _reference_values(f: Callable[..., np.ndarray], n: int, kind: str, t: np.ndarray) -> np.ndarray:
    x = chebyshev_nodes(n) if kind == "chebyshev" else equispaced_nodes(n)
    return np.asarray(barycentric_interpolate(x, f(x), t), dtype=float)


def _points(rng: np.random.Generator) -> np.ndarray:
    """Unseen evaluation points: random, both ends, and a node-free middle."""
    return np.concatenate([[-1.0, 1.0, 0.123456789], rng.uniform(-1.0, 1.0, 60)])


@over_datasets(FUNCTIONS)
def test_interpolate_values(student: Student, rng: np.random.Generator, name: str) -> None:
    data = FUNCTIONS[name]
    function, n, kind = data.build(rng)
    f = traced(function)
    t = _points(rng)
    got = student.interpolate(f, n, kind, t)
    scale = float(np.max(np.abs(function(t)))) or 1.0
    expect_close(got, _reference_values(function, n, kind, t), rtol=0,
                 atol=data.tol * scale, name=f"interpolate(f, {n}, {kind!r}, t)")


@over_datasets(FUNCTIONS, points=1)
def test_interpolate_samples_f_only_at_the_nodes(student: Student, rng: np.random.Generator,
                                                 credit: Credit, name: str) -> None:
    function, n, kind = FUNCTIONS[name].build(rng)
    f = traced(function)
    student.interpolate(f, n, kind, _points(rng))
    fb.expect_sampled_at_nodes(f, n, kind, credit, what=f"interpolate(f, {n}, {kind!r}, t)")


CHEBYSHEV = {k: v for k, v in FUNCTIONS.items() if "equispaced" not in k}


@over_datasets(CHEBYSHEV, points=2)
def test_make_interpolant_returns_a_working_function(student: Student, rng: np.random.Generator,
                                                     credit: Credit, name: str) -> None:
    data = FUNCTIONS[name]
    function, n, kind = data.build(rng)
    f = traced(function)
    p = student.make_interpolant(f, n, kind)
    if not callable(p):
        raise CheckFailure(f"make_interpolant returned a {type(p).__name__}; return the "
                           "function p itself (def p(t): ... then return p).")
    fb.expect_sampled_at_nodes(f, n, kind, credit, what=f"make_interpolant(f, {n})")
    t = _points(rng)
    expect_close(p(t), _reference_values(function, n, kind, t), rtol=0, atol=data.tol,
                 name=f"p(t) from make_interpolant(f, {n})")
    expect_number(p(0.3), name="p(0.3)",
                  hint="A number t must give a number (return float(...) for a 0-d result).")
    x = np.asarray(student.interpolation_nodes(n, kind), dtype=float)
    sample = function(x[3:4])[0]
    if p(x[3]) != sample:
        raise CheckFailure(f"p(x_3) returned {show_number(p(x[3]))} at your node x_3 = "
                           f"{show_number(x[3])}; at a node p must return the sample "
                           f"f(x_3) = {show_number(sample)} exactly.")


def test_agrees_with_scipy(student: Student) -> None:
    f = traced(lambda x: np.exp(np.sin(2 * x)))
    t = np.linspace(-1.0, 1.0, 101)
    x = equispaced_nodes(10)
    expected = BarycentricInterpolator(x, f(x))(t)
    # SciPy forms the first barycentric form; both agree to rounding for degree 10
    expect_close(student.interpolate(f, 10, "equispaced", t), expected, rtol=0, atol=1e-12,
                 name="interpolate(f, 10, 'equispaced', t) against scipy.interpolate")


CONVERGENCE = {
    "unseen-runge-like": Dataset(lambda rng: lambda x: 1.0 / (1.0 + 9.0 * (x - 0.3) ** 2),
                                 points=2, tolerance=1e-6,
                                 reason="errors from 1e-1 down to 1e-13: a correct interpolant "
                                        "matches each to 6 digits; wrong nodes miss by orders"),
    "unseen-entire": Dataset(lambda rng: lambda x: np.cos(4 * x) + x**2, points=2,
                             tolerance=1e-6, reason="an entire function: errors reach rounding "
                                                    "level (below 1e-13) by n = 32"),
}
NS = [2, 4, 8, 16, 32, 48]


@over_datasets(CONVERGENCE)
def test_convergence(student: Student, rng: np.random.Generator, credit: Credit,
                     name: str) -> None:
    data = CONVERGENCE[name]
    function = data.build(rng)
    f = traced(function)
    errors = expect_array(student.convergence(f, NS), shape=(len(NS),),
                          name=f"convergence(f, {NS})")
    grid = fb.GRID
    expected = np.array([np.max(np.abs(_reference_values(function, n, "chebyshev", grid)
                                       - function(grid))) for n in NS])
    # below 1e-13 the error is rounding, which differs between correct implementations
    expect_close(errors, expected, rtol=data.tol, atol=1e-13,
                 name=f"convergence(f, {NS})")
    budget = sum(n + 1 for n in NS) + len(NS) * grid.size
    if f.evaluations > budget:
        credit.partial(0.5, f"convergence evaluated f at {f.evaluations} points; "
                            f"{sum(n + 1 for n in NS)} nodes and the {grid.size} points of "
                            "GRID once per degree are plenty.")
