"""Hidden checks for the approximation assignment: functions the student has never seen.

Each check passes the student's code a function wrapped in ``traced`` (its code
stays in the grader; the student's code calls it across the boundary), then
compares the values with the ``reference`` package and SciPy and reads where
the function was evaluated.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import pytest
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
def test_interpolate_values(student: Student, rng: np.random.Generator, credit: Credit,
                            name: str) -> None:
    data = FUNCTIONS[name]
    function, n, kind = data.build(rng)
    f = traced(function)
    t = _points(rng)
    got = student.interpolate(f, n, kind, t)
    scale = float(np.max(np.abs(function(t)))) or 1.0
    fb.expect_values(student, f, got, _reference_values(function, n, kind, t), n=n, kind=kind,
                     t=t, atol=data.tol * scale, credit=credit,
                     name=f"interpolate(f, {n}, {kind!r}, t)")


def _right(got: object, function: Callable[..., np.ndarray], n: int, kind: str,
           t: np.ndarray, tol: float, what: str) -> None:
    """Fail unless ``got`` are the right values: sampling and cost earn credit only then."""
    expected = _reference_values(function, n, kind, t)
    scale = float(np.max(np.abs(function(t)))) or 1.0
    try:
        expect_close(fb.without_nan_at_nodes(got, expected, t, n, kind), expected, rtol=0,
                     atol=tol * scale, name=what)
    except CheckFailure as failure:
        raise CheckFailure(f"{failure} How f is sampled earns credit only for an interpolant "
                           "whose values are right.") from None


@over_datasets(FUNCTIONS, points=1)
def test_interpolate_samples_f_only_at_the_nodes(student: Student, rng: np.random.Generator,
                                                 name: str) -> None:
    data = FUNCTIONS[name]
    function, n, kind = data.build(rng)
    f = traced(function)
    t = _points(rng)
    what = f"interpolate(f, {n}, {kind!r}, t)"
    got = student.interpolate(f, n, kind, t)
    fb.expect_sampled_at_nodes(student, f, n, kind, what=what)
    _right(got, function, n, kind, t, data.tol, what)


CHEBYSHEV = {k: v for k, v in FUNCTIONS.items() if "equispaced" not in k}


def _interpolant(student: Student, f: object, n: int, kind: str) -> Callable[..., object]:
    p = student.make_interpolant(f, n, kind)
    if not callable(p):
        raise CheckFailure(f"make_interpolant returned a {type(p).__name__}; return the "
                           "function p itself (def p(t): ... then return p).")
    return p


@over_datasets(CHEBYSHEV, points=2)
def test_make_interpolant_returns_a_working_function(student: Student, rng: np.random.Generator,
                                                     credit: Credit, name: str) -> None:
    data = FUNCTIONS[name]
    function, n, kind = data.build(rng)
    f = traced(function)
    p = _interpolant(student, f, n, kind)
    t = _points(rng)
    what = f"p(t) from make_interpolant(f, {n})"
    fb.expect_values(student, f, p(t), _reference_values(function, n, kind, t), n=n, kind=kind,
                     t=t, atol=data.tol, credit=credit, name=what)
    try:
        fb.expect_sampled_at_nodes(student, f, n, kind, what=f"make_interpolant(f, {n})")
    except CheckFailure:
        if fb.own_nodes(f, n) is None:
            raise
        # right values from a wrong node set: the same share as in expect_values
        credit.partial(fb.WRONG_NODES_CREDIT, fb.wrong_node_set(
            student, f, n, kind, what=f"make_interpolant(f, {n})") + " Your values are right, "
            f"so this check keeps {fb.WRONG_NODES_CREDIT:.0%} of its points.")
    expect_number(p(0.3), name="p(0.3)",
                  hint="A number t must give a number (return float(...) for a 0-d result).")


@pytest.mark.points(2)
def test_interpolant_at_the_nodes(student: Student, rng: np.random.Generator) -> None:
    """At a node p returns the sample: the one check that names NaN at a node."""
    function, n, kind = FUNCTIONS["unseen-tanh-24"].build(rng)
    p = _interpolant(student, traced(function), n, kind)
    x = np.asarray(student.interpolation_nodes(n, kind), dtype=float).reshape(-1)
    t = np.concatenate([[-1.0, 1.0], x[1:4]])  # both ends are nodes of every kind
    got = [p(float(s)) for s in t] + list(np.asarray(p(t), dtype=float).reshape(-1))
    bad = sorted({float(s) for s, v in zip([*t, *t], got)
                  if not np.isfinite(np.asarray(v, dtype=float)).all()})
    if bad:
        raise CheckFailure(f"p(t) from make_interpolant(f, {n}) is NaN at t = "
                           f"{', '.join(show_number(s) for s in bad)}, which "
                           f"{'is a node' if len(bad) == 1 else 'are nodes'}: "
                           f"{fb.NODE_REASON}.")
    expect_close(np.asarray(got[len(t):], dtype=float), function(t), rtol=0, atol=1e-14,
                 name=f"p(t) at the nodes t = -1, 1, x_1, x_2, x_3 (n = {n})",
                 hint="At a node p must return the sample f(x_j).")
    for s, v in zip(t, got[:len(t)]):
        expect_close(v, function(np.array(s)), rtol=0, atol=1e-14,
                     name=f"p({show_number(s)}) at a node")


@pytest.mark.points(2)
def test_evaluates_f_once_per_node(student: Student, credit: Credit,
                                   rng: np.random.Generator) -> None:
    """Extra evaluations of f, charged once per submission and in proportion."""
    function, n, kind = FUNCTIONS["unseen-tanh-24"].build(rng)
    t = _points(rng)
    uses = []
    f = traced(function)
    _right(student.interpolate(f, n, kind, t), function, n, kind, t, CHEB_TOL,
           f"interpolate(f, {n}, {kind!r}, t)")
    uses.append((f"interpolate(f, {n}, {kind!r}, t)", f, n + 1))
    f = traced(function)
    p = _interpolant(student, f, n, kind)
    _right(p(t), function, n, kind, t, CHEB_TOL, f"p(t) from make_interpolant(f, {n})")
    uses.append((f"make_interpolant(f, {n})", f, n + 1))
    f, ns = traced(function), [4, 8]
    errors = expect_array(student.convergence(f, ns), shape=(len(ns),),
                          name=f"convergence(f, {ns})")
    _right_errors(fb.nan_from_nodes(student, function, ns, errors), function, ns)
    uses.append((f"convergence(f, {ns})", f, sum(m + 1 for m in ns) + len(ns) * fb.GRID.size))
    fb.cost_share(uses, credit)


CHEB_TOL = 1e-12


def _expected_errors(function: Callable[..., np.ndarray], ns: list[int]) -> np.ndarray:
    grid = fb.GRID
    return np.array([np.max(np.abs(_reference_values(function, n, "chebyshev", grid)
                                   - function(grid))) for n in ns])


def _right_errors(errors: object, function: Callable[..., np.ndarray], ns: list[int]) -> None:
    got = expect_array(errors, shape=(len(ns),), name=f"convergence(f, {ns})")
    expect_close(got, _expected_errors(function, ns), rtol=1e-6, atol=1e-13,
                 name=f"convergence(f, {ns})",
                 hint="How f is sampled earns credit only for a function whose values are right.")


def test_agrees_with_scipy(student: Student) -> None:
    f = traced(lambda x: np.exp(np.sin(2 * x)))
    t = np.linspace(-1.0, 1.0, 101)
    x = equispaced_nodes(10)
    expected = BarycentricInterpolator(x, f(x))(t)
    # SciPy forms the first barycentric form; both agree to rounding for degree 10
    got = fb.without_nan_at_nodes(student.interpolate(f, 10, "equispaced", t), expected, t, 10,
                                  "equispaced")  # NaN at a node is charged once, at the nodes
    expect_close(got, expected, rtol=0, atol=1e-12,
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
def test_convergence(student: Student, rng: np.random.Generator, name: str) -> None:
    data = CONVERGENCE[name]
    function = data.build(rng)
    f = traced(function)
    errors = expect_array(student.convergence(f, NS), shape=(len(NS),),
                          name=f"convergence(f, {NS})")
    # NaN because p is NaN at the nodes of GRID is charged once, at the nodes
    errors = fb.nan_from_nodes(student, function, NS, errors)
    # below 1e-13 the error is rounding, which differs between correct implementations
    expect_close(errors, _expected_errors(function, NS), rtol=data.tol, atol=1e-13,
                 name=f"convergence(f, {NS})")
