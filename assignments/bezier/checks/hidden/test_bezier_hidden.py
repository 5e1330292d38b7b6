"""Hidden checks for the Bezier assignment: the real grading.

Points on the curve (``eval_bezier``, ``de_casteljau``) and subdivision
(``split_bezier``) on named curves: a space curve, degree 40, a polygon whose
points all coincide (the weights must sum to 1), random polygons drawn from the
``rng`` fixture (a regrade draws the same ones, another submission others),
and for ``de_casteljau`` alone degree 1100, where the Bernstein form with
binomials overflows and repeated linear interpolation does not.

The oracle is ``reference.bezier`` (de Casteljau's algorithm); up to degree 40
it is cross-checked with ``scipy.interpolate.BPoly``, which evaluates the
Bernstein form (and returns nan at degree 1100, so it is not used there).
Tolerances are relative to the polygon's size (max |coordinate|, at least 1)
and sit beside each dataset with their reason. The endpoints at t = 0 and 1
are compared exactly, in checks of their own.

References
----------
R. T. Farouki, "The Bernstein polynomial basis: A centennial retrospective",
Computer Aided Geometric Design 29(6), 379-419, 2012. doi:10.1016/j.cagd.2012.03.001
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.interpolate import BPoly

from reference import bezier as reference_bezier, split as reference_split


import bezier_feedback as fb  # checks/public/bezier_feedback.py: on sys.path while checks run

#: Low degree: any correct evaluation is within a few units of 1e-16 (relative); the
#: smallest slip (a wrong exponent, t for 1 - t) is off by 1e-3 or more.
LOW_TOL = 1e-12
#: Degree 40: the Bernstein form with exact binomials (math.comb) is within about 1e-14,
#: with log-gamma binomials within about 1e-13 (lgamma(41) ~ 110 carries an absolute
#: error near 2e-14, which exp turns into a relative one); de Casteljau within n u ~ 5e-15.
#: An int64 factorial (wraps around past 20!) is off by O(1) or is not finite.
HIGH_TOL = 1e-10
#: Degree 1100: de Casteljau's error grows at most like n u ~ 1.2e-13 of the polygon size.
HUGE_TOL = 1e-10
#: Checks against the oracle: reference and BPoly must agree this well up to degree 40.
ORACLE_TOL = 1e-12
#: Seconds for one call at degree 1100: a Python double loop over the triangle does
#: 605,000 interpolations (about 2 s on the grading machine), numpy levels take 3 ms.
HUGE_TIMEOUT = 30.0

BIG_NUMBERS_HINT = (
    "If eval_bezier is right for small n but not here: at degree 40 the numbers inside "
    "the Bernstein form are large, C(40, 20) ~ 1.4e11 and 40! ~ 8.2e47. A numpy int64 "
    "holds at most 9.2e18 (about 20!) and wraps around without an error, so "
    "np.prod(np.arange(1, 41)) is garbage. Use math.comb(n, i): Python integers are exact "
    "at any size.")
NO_BINOMIALS_HINT = (
    "If de_casteljau is right for small n but not here: repeated linear interpolation "
    "forms no large numbers, every point of every level is (1 - t) * P + t * Q of two "
    "points of the previous level. If your de_casteljau uses binomials or factorials, it "
    "is the Bernstein form in disguise.")
OVERFLOW_HINT = (
    "At degree 1100 the Bernstein form overflows: C(1100, 550) ~ 3.3e329 is beyond the "
    "largest double (1.8e308). De Casteljau's algorithm never forms a binomial: compute "
    "the triangle level by level with (1 - t) * P + t * Q.")
PARTITION_HINT = (
    "Every control point of this polygon is the same point, so the curve must stay at that "
    "point for every t: the Bernstein weights B_{0,n}(t), ..., B_{n,n}(t) sum to 1 "
    "((t + (1 - t))**n = 1). Check that n is the degree, len(ctrlpts) - 1, and that the "
    "exponents of t and 1 - t add up to n in every term.")


# ---------------------------------------------------------------------------
# curves
# ---------------------------------------------------------------------------

def _space_curve(rng):
    """A quintic that climbs and twists in 3-D."""
    return [np.array([[0.0, 0.0, 0.0], [2.0, -1.0, 0.5], [3.0, 2.0, 1.5], [1.0, 3.5, 2.0],
                      [-1.5, 2.0, 3.5], [-2.0, -0.5, 5.0]])]


def _degree_40(rng):
    """41 points around a wobbly spiral (fixed seed: the same curve for everyone)."""
    g = np.random.default_rng(40)
    angle = np.linspace(0.0, 4.0 * np.pi, 41)
    radius = 1.0 + 0.1 * np.arange(41) + 0.3 * g.uniform(-1.0, 1.0, 41)
    return [np.c_[radius * np.cos(angle), radius * np.sin(angle)]]


def _constant(rng):
    return [np.tile([2.5, -1.25], (7, 1))]


def _random_unseen(rng, count=3):
    """Polygons of degree 2 to 8 in 2-D or 3-D, coordinates anywhere in [-10, 10]."""
    return [rng.uniform(-10.0, 10.0, (int(rng.integers(3, 10)), int(rng.integers(2, 4))))
            for _ in range(count)]


def _degree_1100(rng):
    """A rose curve's points, sampled 1101 times: the polygon of a degree-1100 curve."""
    angle = np.linspace(0.0, 2.0 * np.pi, 1101)
    radius = 1.0 + 0.3 * np.cos(7.0 * angle)
    return [np.c_[radius * np.cos(angle), radius * np.sin(angle)]]


def _unseen_params(rng):
    return (0.0, 1.0, *np.sort(rng.uniform(0.0, 1.0, 4)).tolist())


@dataclass(frozen=True)
class Curves:
    build: Callable[[np.random.Generator], list]
    params: Callable[[np.random.Generator], tuple]
    weight: int
    tol: float                  # allowed error relative to the polygon's size
    hints: tuple[str, str] = ("", "")   # (eval_bezier, de_casteljau)
    bpoly: bool = True          # cross-check the oracle with BPoly (not at degree 1100)
    timeout: float | None = None


CURVES = {
    "3d-curve": Curves(_space_curve, lambda rng: (0.0, 0.15, 0.5, 0.62, 0.9, 1.0), 1, LOW_TOL),
    "high-degree-40": Curves(_degree_40,
                             lambda rng: (0.0, 0.01, 0.25, 0.5, 0.73, 0.99, 1.0), 2, HIGH_TOL,
                             hints=(BIG_NUMBERS_HINT, NO_BINOMIALS_HINT)),
    "constant-polygon": Curves(_constant, lambda rng: (0.1, 0.3, 0.5, 0.9), 1, LOW_TOL,
                               hints=(PARTITION_HINT, PARTITION_HINT)),
    "random-unseen": Curves(_random_unseen, _unseen_params, 2, LOW_TOL),
}

#: de_casteljau alone: the Bernstein form cannot get there.
CASTELJAU_ONLY = {
    "high-degree-1100": Curves(_degree_1100, lambda rng: (0.37,), 1, HUGE_TOL,
                               hints=("", OVERFLOW_HINT), bpoly=False, timeout=HUGE_TIMEOUT),
}


def oracle_point(ctrl: np.ndarray, t: float, *, bpoly: bool) -> np.ndarray:
    point = reference_bezier(ctrl, t)
    if bpoly:
        theirs = BPoly(ctrl[:, None, :], [0.0, 1.0])(t)
        if np.max(np.abs(theirs - point)) > ORACLE_TOL * fb.size(ctrl):
            raise RuntimeError("reference.bezier and scipy's BPoly disagree: fix the oracle.")
    return point


def _grade_points(student, credit, rng, fn: str, curves: Curves) -> None:
    hint = curves.hints[0 if fn == "eval_bezier" else 1]
    params = curves.params(rng)
    verdict = fb.Verdict()
    for ctrl in curves.build(rng):
        atol = curves.tol * fb.size(ctrl)
        for t in params:
            got = fb.ask(student, fn, ctrl, t, hint=hint, timeout=curves.timeout)
            expected = oracle_point(ctrl, t, bpoly=curves.bpoly)
            fb.judge_point(got, expected, fn=fn, ctrl=ctrl, t=t, atol=atol, verdict=verdict,
                           hint=hint)
    verdict.finish(credit)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.points(c.weight))
                                  for n, c in CURVES.items()])
def test_eval_bezier(student, credit, rng, name):
    _grade_points(student, credit, rng, "eval_bezier", CURVES[name])


ALL_CASTELJAU = {**CURVES, **CASTELJAU_ONLY}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.points(c.weight))
                                  for n, c in ALL_CASTELJAU.items()])
def test_de_casteljau(student, credit, rng, name):
    _grade_points(student, credit, rng, "de_casteljau", ALL_CASTELJAU[name])


# ---------------------------------------------------------------------------
# exact endpoints
# ---------------------------------------------------------------------------

def _lecture_form_at_1(ctrl: np.ndarray) -> np.ndarray:
    """What the lecture's step P + t * (Q - P) gives at t = 1 (exactly ctrl[-1] in exact maths)."""
    level = ctrl.copy()
    while len(level) > 1:
        level = level[:-1] + 1.0 * (level[1:] - level[:-1])
    return level[0]


def _endpoint_polygons(rng):
    """Random polygons of degree 1 to 12. The first three are drawn until the lecture's step
    P + t * (Q - P) misses their last point at t = 1 in the last bit (about 1 polygon in 9
    does), so an answer that rounds there is caught whatever the seed."""
    def draw():
        return rng.uniform(-10.0, 10.0, (int(rng.integers(2, 14)), 2))

    tricky = []
    for _ in range(2000):
        ctrl = draw()
        if not np.array_equal(_lecture_form_at_1(ctrl), ctrl[-1]):
            tricky.append(ctrl)
            if len(tricky) == 3:
                break
    return tricky + [draw() for _ in range(3)]


def _grade_endpoints(student, credit, rng, fn: str) -> None:
    fb.grade_endpoints(student, credit, fn, _endpoint_polygons(rng), rtol=LOW_TOL)


@pytest.mark.points(1)
@pytest.mark.parametrize("name", ["unseen"])
def test_eval_bezier_endpoints(student, credit, rng, name):
    _grade_endpoints(student, credit, rng, "eval_bezier")


@pytest.mark.points(1)
@pytest.mark.parametrize("name", ["unseen"])
def test_de_casteljau_endpoints(student, credit, rng, name):
    _grade_endpoints(student, credit, rng, "de_casteljau")


# ---------------------------------------------------------------------------
# subdivision
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Cuts:
    build: Callable[[np.random.Generator], list]   # [(control points, t), ...]
    weight: int
    tol: float                  # allowed error relative to the polygon's size


def _split_space(rng):
    return [(_space_curve(rng)[0], 0.35)]


def _split_40(rng):
    return [(_degree_40(rng)[0], 0.6)]


def _split_random(rng):
    return [(ctrl, float(rng.uniform(0.05, 0.95))) for ctrl in _random_unseen(rng)]


def _split_line(rng):
    return [(np.array([[4.0, -1.0], [-2.0, 3.5]]), 0.3)]


def _split_degree_0(rng):
    return [(np.array([[-0.75, 2.25]]), 0.5)]


def _split_ends(rng):
    """Cut at t = 0 (left shrinks to ctrl[0]) and t = 1 (right shrinks to ctrl[-1])."""
    ctrl = np.array([[0.0, 1.0], [1.5, 3.0], [4.0, 2.5], [5.0, -0.5]])
    return [(ctrl, 0.0), (ctrl, 1.0)]


CUTS = {
    "3d-curve": Cuts(_split_space, 1, LOW_TOL),
    "high-degree-40": Cuts(_split_40, 1, HIGH_TOL),  # n levels of rounding, as for the points
    "random-unseen": Cuts(_split_random, 2, LOW_TOL),
    "line": Cuts(_split_line, 1, LOW_TOL),
    "degree-0": Cuts(_split_degree_0, 1, LOW_TOL),
    "ends": Cuts(_split_ends, 1, LOW_TOL),
}


def oracle_split(ctrl: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """The two polygons; each must reproduce its piece of the curve (checked with BPoly)."""
    left, right = reference_split(ctrl, t)
    s = np.linspace(0.0, 1.0, 7)
    for poly, where in ((left, t * s), (right, t + (1.0 - t) * s)):
        if np.max(np.abs(fb.curve_points(poly, s) - fb.curve_points(ctrl, where))) \
                > ORACLE_TOL * fb.size(ctrl):
            raise RuntimeError("reference.split does not reproduce the curve: "
                               "fix the oracle.")
    return left, right


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.points(c.weight))
                                  for n, c in CUTS.items()])
def test_split_bezier(student, credit, feedback, rng, name):
    cuts = CUTS[name]
    verdict = fb.Verdict()
    for ctrl, t in cuts.build(rng):
        fb.grade_split(student, ctrl, t, oracle_split(ctrl, t), atol=cuts.tol * fb.size(ctrl),
                       verdict=verdict, picture=feedback.image)
    verdict.finish(credit)
