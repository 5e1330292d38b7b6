"""Hidden checks for the spline car: the real grading.

``spline_coefficients`` is compared with ``reference.CubicSpline``
(natural end conditions; its ``c`` array read as rows [a, b, c, d]) on named
point sets, after staged property checks that say what is wrong (passes
through the points, C2 at the interior knots, S'' = 0 at the ends). A
convergence test measures the order of accuracy on smooth functions.
``spline_eval`` gets the reference coefficients, so its checks do not depend
on the student's ``spline_coefficients``. ``draw_car`` draws unseen shapes, so
a hard-coded picture fails. Sets named ``unseen-*`` come from the ``rng``
fixture: a regrade draws the same inputs, another submission draws others.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

import spline_feedback as judge  # checks/public/spline_feedback.py: on sys.path while checks run
from autograder.checks import (
    CheckFailure,
    Credit,
    Dataset,
    Feedback,
    Student,
    expect_number,
    over_datasets,
    show_number,
)
from reference import CubicSpline, car

#: knots x and values y
Data = tuple[np.ndarray, np.ndarray]


def expected_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Rows [a, b, c, d] of the natural spline: row i = [c[3,i], c[2,i], c[1,i], c[0,i]]."""
    return CubicSpline(x, y, bc_type="natural").c[::-1].T.copy()


def evaluate(rows: np.ndarray, x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The piecewise cubic with rows [a, b, c, d] at ``t`` (end pieces extended)."""
    i = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(rows) - 1)
    u = t - x[i]
    a, b, c, d = rows[i].T
    return a + u * (b + u * (c + u * d))


# ---------------------------------------------------------------------------
# point sets
# ---------------------------------------------------------------------------

def _line_2pts(rng: np.random.Generator) -> Data:
    return np.array([-1.5, 2.5]), np.array([3.0, -1.0])


def _parabola_5(rng: np.random.Generator) -> Data:
    x = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
    return x, x**2 + 1.0


def _random_12(rng: np.random.Generator) -> Data:
    g = np.random.default_rng(12)
    return np.cumsum(g.uniform(0.2, 1.5, 12)), g.normal(0.0, 2.0, 12)


def _uneven_spacing(rng: np.random.Generator) -> Data:
    """Gaps from 0.001 to 1 side by side: any formula that assumes equal gaps fails."""
    g = np.random.default_rng(7)
    x = np.concatenate([[0.0], np.cumsum(10.0 ** g.uniform(-3.0, 0.0, 15))])
    return x, np.sin(3.0 * x) + 0.3 * g.normal(size=x.size)


def _large_500(rng: np.random.Generator) -> Data:
    g = np.random.default_rng(500)
    x = np.cumsum(g.uniform(0.05, 0.5, 500))
    return x, np.sin(x) + 0.1 * g.normal(size=500)


def _runge_15(rng: np.random.Generator) -> Data:
    x = np.linspace(-1.0, 1.0, 15)
    return x, 1.0 / (1.0 + 25.0 * x**2)


def _far_from_origin(rng: np.random.Generator) -> Data:
    """Knots near 1000: coefficients must be local, in powers of (t - x_i), not of t."""
    g = np.random.default_rng(1000)
    x = 1000.0 + np.cumsum(g.uniform(0.5, 1.5, 9))
    return x, g.normal(size=9)


def _unseen_random(rng: np.random.Generator) -> Data:
    n = int(rng.integers(6, 41))
    x = rng.uniform(-10.0, 10.0) + np.cumsum(rng.uniform(0.1, 2.0, n))
    return x, rng.normal(0.0, rng.uniform(0.5, 5.0), n)


WELL_SPACED = ("gaps of similar size: the system for M is strictly diagonally dominant "
               "(condition number below 3), so correct methods agree to ~1e-14")

#: tolerances are relative to |expected| + the largest |expected| in the column
DATASETS: dict[str, Dataset[Data]] = {
    "line-2pts": Dataset(_line_2pts, tolerance=1e-9,
                         reason="no system to solve: exact up to rounding"),
    "parabola-5": Dataset(_parabola_5, tolerance=1e-9, reason=WELL_SPACED),
    "random-12": Dataset(_random_12, points=2, tolerance=1e-9, reason=WELL_SPACED),
    "uneven-spacing": Dataset(_uneven_spacing, points=2, tolerance=1e-7,
                              reason="gaps from 1e-3 to 1: d = (M_(i+1) - M_i) / (6 h_i) "
                                     "divides rounding errors by small h_i; correct methods "
                                     "agree to ~1e-12"),
    "large-500": Dataset(_large_500, points=2, tolerance=1e-8,
                         reason="500 unknowns: rounding accumulates along the elimination, "
                                "still well conditioned; correct methods agree to ~1e-13"),
    "runge-15": Dataset(_runge_15, tolerance=1e-9, reason=WELL_SPACED),
    "far-from-origin": Dataset(_far_from_origin, tolerance=1e-8,
                               reason="h_i = x_(i+1) - x_i loses 3 digits next to 1000"),
    "unseen-random": Dataset(_unseen_random, points=2, tolerance=1e-8, reason=WELL_SPACED),
}


@over_datasets(DATASETS)
def test_spline_coefficients(student: Student, credit: Credit, rng: np.random.Generator,
                             name: str) -> None:
    x, y = DATASETS[name].build(rng)
    got = student.spline_coefficients(x, y)
    judge.grade_coefficients(got, x, y, expected_rows(x, y), credit, rtol=DATASETS[name].tol)


def _check_property(student: Student, credit: Credit, rng: np.random.Generator, name: str,
                    check: Callable[[judge.Reading, np.ndarray, np.ndarray, float], None]) -> None:
    """One property of the student's spline of a point set, read from its coefficients."""
    x, y = DATASETS[name].build(rng)
    reading = judge.read_coefficients(student.spline_coefficients(x, y), x, y)
    check(reading, x, y, DATASETS[name].tol)
    judge.finish(reading, credit)


@over_datasets(DATASETS, only=["random-12", "unseen-random"], points=1)
def test_natural_ends(student: Student, credit: Credit, rng: np.random.Generator,
                      name: str) -> None:
    _check_property(student, credit, rng, name, judge.check_natural_ends)


@over_datasets(DATASETS, only=["random-12", "uneven-spacing", "unseen-random"], points=1)
def test_continuity(student: Student, credit: Credit, rng: np.random.Generator,
                    name: str) -> None:
    _check_property(student, credit, rng, name, judge.check_continuity)


# ---------------------------------------------------------------------------
# order of accuracy
# ---------------------------------------------------------------------------

#: name -> (f, a, b): smooth functions whose f'' is not zero at the ends
FUNCTIONS: dict[str, tuple[Callable[[np.ndarray], np.ndarray], float, float]] = {
    "sin": (np.sin, 0.0, 3.0), "exp": (np.exp, -1.0, 1.0)}
#: Intervals of the coarse grid; the fine grid has twice as many (its knots nest).
COARSE = 32
#: The error is measured on the middle half: near the ends a natural spline is only
#: O(h^2) accurate (S'' = 0 there while f'' is not), in a layer that shrinks with h.
INTERIOR = 0.25
#: Interior order: 4 for a cubic spline (measured 3.97 to 4.01 with these grids);
#: 2 for piecewise linear interpolation.
INTERIOR_ORDER = 3.5
#: Whole-interval order: 2 for natural ends (measured 2.00); 1 for zero slopes at the ends.
WHOLE_ORDER = 1.5
#: Largest interior error on the fine grid (a correct spline: below 4e-6 here).
FINE_ERROR = 1e-4


def _spline_of(student: Student, f: Callable[[np.ndarray], np.ndarray], a: float, b: float,
               intervals: int) -> tuple[np.ndarray, judge.Reading]:
    """The knots and the student's coefficients for f at ``intervals + 1`` equal steps."""
    x = np.linspace(a, b, intervals + 1)
    return x, judge.read_coefficients(student.spline_coefficients(x, f(x)), x, f(x))


def _max_error(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, reading: judge.Reading,
               margin: float) -> float:
    t = np.linspace(x[0] + margin, x[-1] - margin, 20 * (len(x) - 1) + 1)
    return float(np.max(np.abs(evaluate(reading.rows, x, t) - f(t))))


def _order(coarse: float, fine: float) -> float:
    if fine == 0.0:
        return math.inf
    return math.log2(coarse / fine) if coarse > 0 else -math.inf


#: A spline "looks like piecewise linear interpolation" only when it is within this
#: fraction of the gap between the true spline and the broken line through the same points.
LINEAR_LIKENESS = 0.1


def _looks_like(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, reading: judge.Reading,
                margin: float, order: float) -> str:
    """A hint naming what the spline resembles, only when that is measured in its values."""
    t = np.linspace(x[0] + margin, x[-1] - margin, 20 * (len(x) - 1) + 1)
    mine = evaluate(reading.rows, x, t)
    linear = np.interp(t, x, f(x))
    gap = float(np.max(np.abs(evaluate(expected_rows(x, f(x)), x, t) - linear)))
    if gap > 0 and float(np.max(np.abs(mine - linear))) <= LINEAR_LIKENESS * gap:
        return ", which looks like piecewise linear interpolation (order 2)"
    if order < 1.5:
        return ", order 1 or worse: the pieces are not the cubic spline's (check the solve)"
    return ""


@over_datasets(FUNCTIONS, points=2)
def test_convergence(student: Student, credit: Credit, name: str) -> None:
    f, a, b = FUNCTIONS[name]
    margin = INTERIOR * (b - a)
    x_coarse, coarse = _spline_of(student, f, a, b, COARSE)
    x_fine, reading = _spline_of(student, f, a, b, 2 * COARSE)
    e_coarse = _max_error(f, x_coarse, coarse, margin)
    e_fine = _max_error(f, x_fine, reading, margin)
    where = (f"on the middle half [{a + margin:g}, {b - margin:g}] of [{a:g}, {b:g}] (away from "
             "the ends, where a natural spline is only O(h^2) accurate)")
    order = _order(e_coarse, e_fine)
    if not order >= INTERIOR_ORDER:
        looks = _looks_like(f, x_fine, reading, margin, order)
        raise CheckFailure(
            f"Interpolating f = {name} at {COARSE + 1} and then {2 * COARSE + 1} equally spaced "
            f"points, your spline's maximum error {where} went from {e_coarse:.2e} to "
            f"{e_fine:.2e}: halving the spacing h divided it by {e_coarse / e_fine:.1f}, order "
            f"{order:.1f}{looks}. A cubic spline's error there shrinks like h^4: "
            "the ratio should be about 16.")
    if not e_fine <= FINE_ERROR:
        raise CheckFailure(
            f"Interpolating f = {name} at {2 * COARSE + 1} equally spaced points, your spline is "
            f"off by up to {e_fine:.2e} {where}; a cubic spline is accurate to about 1e-6 there. "
            "Check that S(t) uses the piece that contains t.")
    whole_fine = _max_error(f, x_fine, reading, 0.0)
    whole = _order(_max_error(f, x_coarse, coarse, 0.0), whole_fine)
    if whole < WHOLE_ORDER:
        credit.partial(0.5,
                       f"Away from the ends your error shrinks like h^{order:.0f}, as it should, "
                       f"but over the whole interval only like h^{whole:.1f} (error "
                       f"{whole_fine:.1e} near the ends with {2 * COARSE} intervals): the end "
                       "conditions are off. With natural ends (S'' = 0) the error near the ends "
                       "is O(h^2); zero slopes at the ends give O(h).")
    judge.finish(reading, credit)


# ---------------------------------------------------------------------------
# spline_eval, with the reference coefficients
# ---------------------------------------------------------------------------

def _knots(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return x.copy()


def _between(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    mid = 0.5 * (x[:-1] + x[1:])
    inside = np.random.default_rng(3).uniform(x[0], x[-1], 40)
    return np.concatenate([mid, inside])


def _outside(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    span = x[-1] - x[0]
    return np.array([x[0] - 0.3 * span, x[0] - 0.01, x[-1] + 0.01, x[-1] + 0.2 * span])


def _unseen_unsorted(x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Random points in random order, a few outside: t need not be sorted."""
    span = x[-1] - x[0]
    return rng.permutation(np.concatenate([rng.uniform(x[0], x[-1], 60),
                                           rng.uniform(x[0] - 0.1 * span, x[0], 2),
                                           rng.uniform(x[-1], x[-1] + 0.1 * span, 2)]))


#: One Horner evaluation per point: rounding only. Relative to |value| + max |value|.
EVAL_RTOL = 1e-12
EVAL_REASON = "one Horner evaluation per point: rounding only"


def _points_on(data: str, make_t: Callable[[np.ndarray, np.random.Generator], np.ndarray]
               ) -> Callable[[np.random.Generator], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Knots x and values y of the point set ``data``, and the points t made from the knots."""
    def build(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x, y = DATASETS[data].build(rng)
        return x, y, make_t(x, rng)
    return build


#: name -> (x, y, t): knots and values of a point set, and the points t
EVAL_SETS: dict[str, Dataset[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {
    "knots": Dataset(_points_on("random-12", _knots), tolerance=EVAL_RTOL, reason=EVAL_REASON),
    "between": Dataset(_points_on("uneven-spacing", _between), points=2, tolerance=EVAL_RTOL,
                       reason=EVAL_REASON),
    "outside": Dataset(_points_on("random-12", _outside), tolerance=EVAL_RTOL,
                       reason=EVAL_REASON),
    "unseen-unsorted": Dataset(_points_on("unseen-random", _unseen_unsorted),
                               tolerance=EVAL_RTOL, reason=EVAL_REASON),
}


@over_datasets(EVAL_SETS)
def test_spline_eval(student: Student, credit: Credit, rng: np.random.Generator,
                     name: str) -> None:
    x, y, t = EVAL_SETS[name].build(rng)
    rows = expected_rows(x, y)
    got = student.spline_eval(x, rows, t)
    judge.grade_eval(got, x, t, evaluate(rows, x, t), rtol=EVAL_RTOL, credit=credit,
                     retry_reversed=lambda: student.spline_eval(x, rows[:, ::-1].copy(), t))


@pytest.mark.points(1)
def test_spline_eval_scalar(student: Student, credit: Credit,
                            rng: np.random.Generator) -> None:
    x, y = DATASETS["random-12"].build(rng)  # fixed data: the rng is not used
    rows = expected_rows(x, y)
    t = float(0.5 * (x[4] + x[5]))
    value = expect_number(student.spline_eval(x, rows, t),
                          name=f"spline_eval(x, coeffs, t) with a single number t = {show_number(t, 4)}")
    judge.grade_eval(np.array(value), x, np.array(t), evaluate(rows, x, np.array(t)),
                     rtol=EVAL_RTOL, credit=credit,
                     retry_reversed=lambda: student.spline_eval(x, rows[:, ::-1].copy(), t))


# ---------------------------------------------------------------------------
# drawings of unseen shapes
# ---------------------------------------------------------------------------

def _thin_straights(points: np.ndarray) -> np.ndarray:
    """Drop the points in the middle of straight runs (collinear with both neighbours)."""
    keep = [0]
    for i in range(1, len(points) - 1):
        a, b, c = points[i - 1], points[i], points[i + 1]
        cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if abs(cross) > 1e-6 * float(np.sum((c - a) ** 2)):
            keep.append(i)
    return points[keep + [len(points) - 1]]


def _unseen_car(rng: np.random.Generator) -> list[np.ndarray]:
    """The car moved and scaled, a little shaken, with straight runs down to their two ends
    and every other point of the long strokes: long steps next to short ones, where the
    choice of parameter shows. With all the points, straight lines between them came
    within 1.6-2.7% of the car (the pass line is 2%), so their score hung on the seed;
    now they are 6.3-6.7% off for every seed (half the points), the point number as the
    parameter 3.7-4.1%, and a correct drawing stays within 0.1%."""
    scale, shift = rng.uniform(0.5, 2.0), rng.uniform(-20.0, 20.0, 2)
    strokes = []
    for stroke in car():
        closed = np.array_equal(stroke[0], stroke[-1])
        pts = _thin_straights(stroke)
        if len(pts) > 6:
            pts = np.vstack([pts[:-1:2], pts[-1:]])
        pts = pts + rng.normal(0.0, 0.003, pts.shape)
        if closed:
            pts[-1] = pts[0]
        strokes.append(pts * scale + shift)
    return strokes


def _unseen_rounded_rectangle(rng: np.random.Generator) -> list[np.ndarray]:
    """A rectangle with round corners: five points per corner, none along the sides."""
    w, h = rng.uniform(4.0, 7.0), rng.uniform(1.5, 2.5)
    r, k = rng.uniform(0.2, 0.3) * h, 5
    corners = [(w - r, h - r, 0.0), (r, h - r, 90.0), (r, r, 180.0), (w - r, r, 270.0)]
    pts = np.concatenate([
        np.column_stack([cx + r * np.cos(np.radians(a0 + np.linspace(0.0, 90.0, k))),
                         cy + r * np.sin(np.radians(a0 + np.linspace(0.0, 90.0, k)))])
        for cx, cy, a0 in corners])
    pts = np.vstack([pts[k // 2:], pts[:k // 2 + 1]])  # start and end in a corner, closed
    return [pts * rng.uniform(0.5, 3.0) + rng.uniform(-20.0, 20.0, 2)]


def _unseen_letter_s(rng: np.random.Generator) -> list[np.ndarray]:
    """Two round ends, eight points each, joined by one long step: the parameter shows."""
    a1 = np.radians(np.linspace(0.0, 270.0, 8))
    a2 = np.radians(np.linspace(90.0, -180.0, 8))
    pts = np.vstack([np.column_stack([np.cos(a1), 3.0 + np.sin(a1)]),
                     np.column_stack([np.cos(a2), -3.0 + np.sin(a2)])])
    turn = np.radians(rng.uniform(-20.0, 20.0))
    rotation = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return [pts @ rotation.T * rng.uniform(0.5, 3.0) + rng.uniform(-20.0, 20.0, 2)]


#: name -> strokes; thresholds: DRAWING_PASS and DRAWING_HALF in spline_feedback.py
SHAPES: dict[str, Dataset[list[np.ndarray]]] = {
    "unseen-car": Dataset(_unseen_car, points=2),
    "unseen-rounded-rectangle": Dataset(_unseen_rounded_rectangle, points=2),
    "unseen-letter-s": Dataset(_unseen_letter_s, points=2),
}
#: what each picture shows, for messages
SHAPE_NAMES = {"unseen-car": "car", "unseen-rounded-rectangle": "rounded rectangle",
               "unseen-letter-s": "letter S"}


@over_datasets(SHAPES)
def test_draw_car_unseen(student: Student, credit: Credit, feedback: Feedback,
                         rng: np.random.Generator, name: str) -> None:
    strokes = SHAPES[name].build(rng)
    fig = student.draw_car(strokes)
    judge.grade_drawing(fig, strokes, credit, feedback, what=SHAPE_NAMES[name],
                        picture_shown=False)
