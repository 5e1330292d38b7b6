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

import numpy as np
from scipy.interpolate import BPoly

import bezier_feedback as fb  # checks/public/bezier_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Dataset, Feedback, Student, over_datasets
from reference import bezier as reference_bezier, split as reference_split

#: Tolerances, relative to the polygon's size (max |coordinate|, at least 1).
LOW_TOL = 1e-12
LOW_REASON = ("low degree: any correct evaluation is within a few units of 1e-16 (relative); "
              "the smallest slip (a wrong exponent, t for 1 - t) is off by 1e-3 or more")
HIGH_TOL = 1e-10
HIGH_REASON = ("degree 40: the Bernstein form with exact binomials (math.comb) is within "
               "about 1e-14, with log-gamma binomials within about 1e-13 (lgamma(41) ~ 110 "
               "carries an absolute error near 2e-14, which exp turns into a relative one); de "
               "Casteljau within n u ~ 5e-15. An int64 factorial (wraps around past 20!) is "
               "off by O(1) or is not finite")
HUGE_TOL = 1e-10
HUGE_REASON = "degree 1100: de Casteljau's error grows at most like n u ~ 1.2e-13"
#: Highest degree at which the oracle is cross-checked with BPoly (nan at degree 1100).
BPOLY_MAX_DEGREE = 40
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

def _space_curve(rng: np.random.Generator) -> list[np.ndarray]:
    """A quintic that climbs and twists in 3-D."""
    return [np.array([[0.0, 0.0, 0.0], [2.0, -1.0, 0.5], [3.0, 2.0, 1.5], [1.0, 3.5, 2.0],
                      [-1.5, 2.0, 3.5], [-2.0, -0.5, 5.0]])]


def _degree_40(rng: np.random.Generator) -> list[np.ndarray]:
    """41 points around a wobbly spiral (fixed seed: the same curve for everyone)."""
    g = np.random.default_rng(40)
    angle = np.linspace(0.0, 4.0 * np.pi, 41)
    radius = 1.0 + 0.1 * np.arange(41) + 0.3 * g.uniform(-1.0, 1.0, 41)
    return [np.c_[radius * np.cos(angle), radius * np.sin(angle)]]


def _constant(rng: np.random.Generator) -> list[np.ndarray]:
    return [np.tile([2.5, -1.25], (7, 1))]


def _random_unseen(rng: np.random.Generator, count: int = 3) -> list[np.ndarray]:
    """Polygons of degree 2 to 8 in 2-D or 3-D, coordinates anywhere in [-10, 10]."""
    return [rng.uniform(-10.0, 10.0, (int(rng.integers(3, 10)), int(rng.integers(2, 4))))
            for _ in range(count)]


def _degree_1100(rng: np.random.Generator) -> list[np.ndarray]:
    """A rose curve's points, sampled 1101 times: the polygon of a degree-1100 curve."""
    angle = np.linspace(0.0, 2.0 * np.pi, 1101)
    radius = 1.0 + 0.3 * np.cos(7.0 * angle)
    return [np.c_[radius * np.cos(angle), radius * np.sin(angle)]]


def _unseen_params(rng: np.random.Generator) -> list[float]:
    return [0.0, 1.0, *np.sort(rng.uniform(0.0, 1.0, 4)).tolist()]


#: control polygons, and the parameters t at which each is evaluated
Curves = tuple[list[np.ndarray], list[float]]


def _curves(polygons: Callable[[np.random.Generator], list[np.ndarray]],
            params: Callable[[np.random.Generator], list[float]]
            ) -> Callable[[np.random.Generator], Curves]:
    """Draw the parameters, then the polygons (in this order: unseen data stay the same)."""
    def build(rng: np.random.Generator) -> Curves:
        ts = params(rng)
        return polygons(rng), ts
    return build


CURVES: dict[str, Dataset[Curves]] = {
    "3d-curve": Dataset(_curves(_space_curve, lambda rng: [0.0, 0.15, 0.5, 0.62, 0.9, 1.0]),
                        tolerance=LOW_TOL, reason=LOW_REASON),
    "high-degree-40": Dataset(
        _curves(_degree_40, lambda rng: [0.0, 0.01, 0.25, 0.5, 0.73, 0.99, 1.0]),
        points=2, tolerance=HIGH_TOL, reason=HIGH_REASON),
    "constant-polygon": Dataset(_curves(_constant, lambda rng: [0.1, 0.3, 0.5, 0.9]),
                                tolerance=LOW_TOL, reason=LOW_REASON, hint=PARTITION_HINT),
    "random-unseen": Dataset(_curves(_random_unseen, _unseen_params), points=2,
                             tolerance=LOW_TOL, reason=LOW_REASON),
}

#: de_casteljau alone: the Bernstein form cannot get there.
CASTELJAU_ONLY: dict[str, Dataset[Curves]] = {
    "high-degree-1100": Dataset(_curves(_degree_1100, lambda rng: [0.37]),
                                tolerance=HUGE_TOL, reason=HUGE_REASON, hint=OVERFLOW_HINT),
}
ALL_CASTELJAU = {**CURVES, **CASTELJAU_ONLY}

#: hints of one function where they differ from the dataset's hint
HINTS = {("high-degree-40", "eval_bezier"): BIG_NUMBERS_HINT,
         ("high-degree-40", "de_casteljau"): NO_BINOMIALS_HINT}
#: seconds per call where the default limit is too short for a correct answer
TIMEOUTS = {"high-degree-1100": HUGE_TIMEOUT}


def oracle_point(ctrl: np.ndarray, t: float) -> np.ndarray:
    point = reference_bezier(ctrl, t)
    if len(ctrl) - 1 <= BPOLY_MAX_DEGREE:
        theirs = BPoly(ctrl[:, None, :], [0.0, 1.0])(t)
        if np.max(np.abs(theirs - point)) > ORACLE_TOL * fb.size(ctrl):
            raise RuntimeError("reference.bezier and scipy's BPoly disagree: fix the oracle.")
    return point


def _grade_points(student: Student, credit: Credit, rng: np.random.Generator, fn: str,
                  name: str) -> None:
    data = ALL_CASTELJAU[name]
    hint = HINTS.get((name, fn), data.hint)
    polygons, params = data.build(rng)
    broken = fb.CONVENTIONS.record()
    for ctrl in polygons:
        atol = data.tol * fb.size(ctrl)
        for t in params:
            got = fb.ask(student, fn, ctrl, t, hint=hint, timeout=TIMEOUTS.get(name))
            fb.judge_point(got, oracle_point(ctrl, t), fn=fn, ctrl=ctrl, t=t, atol=atol,
                           broken=broken, hint=hint)
    broken.finish(credit)


@over_datasets(CURVES)
def test_eval_bezier(student: Student, credit: Credit, rng: np.random.Generator,
                     name: str) -> None:
    _grade_points(student, credit, rng, "eval_bezier", name)


@over_datasets(ALL_CASTELJAU)
def test_de_casteljau(student: Student, credit: Credit, rng: np.random.Generator,
                      name: str) -> None:
    _grade_points(student, credit, rng, "de_casteljau", name)


# ---------------------------------------------------------------------------
# exact endpoints
# ---------------------------------------------------------------------------

def _lecture_form_at_1(ctrl: np.ndarray) -> np.ndarray:
    """What the lecture's step P + t * (Q - P) gives at t = 1 (exactly ctrl[-1] in exact maths)."""
    level = ctrl.copy()
    while len(level) > 1:
        level = level[:-1] + 1.0 * (level[1:] - level[:-1])
    return level[0]


def _endpoint_polygons(rng: np.random.Generator) -> list[np.ndarray]:
    """Random polygons of degree 1 to 12. The first three are drawn until the lecture's step
    P + t * (Q - P) misses their last point at t = 1 in the last bit (about 1 polygon in 9
    does), so an answer that rounds there is caught whatever the seed."""
    def draw() -> np.ndarray:
        return rng.uniform(-10.0, 10.0, (int(rng.integers(2, 14)), 2))

    tricky: list[np.ndarray] = []
    for _ in range(2000):
        ctrl = draw()
        if not np.array_equal(_lecture_form_at_1(ctrl), ctrl[-1]):
            tricky.append(ctrl)
            if len(tricky) == 3:
                break
    return tricky + [draw() for _ in range(3)]


#: exact at t = 0 and t = 1; LOW_TOL only tells rounding from a wrong point
ENDPOINTS: dict[str, Dataset[list[np.ndarray]]] = {"unseen": Dataset(_endpoint_polygons)}


@over_datasets(ENDPOINTS)
def test_eval_bezier_endpoints(student: Student, credit: Credit, rng: np.random.Generator,
                               name: str) -> None:
    fb.grade_endpoints(student, credit, "eval_bezier", ENDPOINTS[name].build(rng), rtol=LOW_TOL)


@over_datasets(ENDPOINTS)
def test_de_casteljau_endpoints(student: Student, credit: Credit, rng: np.random.Generator,
                                name: str) -> None:
    fb.grade_endpoints(student, credit, "de_casteljau", ENDPOINTS[name].build(rng), rtol=LOW_TOL)


# ---------------------------------------------------------------------------
# subdivision
# ---------------------------------------------------------------------------

#: a control polygon and the parameter t where it is cut
Cut = tuple[np.ndarray, float]


def _split_space(rng: np.random.Generator) -> list[Cut]:
    return [(_space_curve(rng)[0], 0.35)]


def _split_40(rng: np.random.Generator) -> list[Cut]:
    return [(_degree_40(rng)[0], 0.6)]


def _split_random(rng: np.random.Generator) -> list[Cut]:
    return [(ctrl, float(rng.uniform(0.05, 0.95))) for ctrl in _random_unseen(rng)]


def _split_line(rng: np.random.Generator) -> list[Cut]:
    return [(np.array([[4.0, -1.0], [-2.0, 3.5]]), 0.3)]


def _split_degree_0(rng: np.random.Generator) -> list[Cut]:
    return [(np.array([[-0.75, 2.25]]), 0.5)]


def _split_ends(rng: np.random.Generator) -> list[Cut]:
    """Cut at t = 0 (left shrinks to ctrl[0]) and t = 1 (right shrinks to ctrl[-1])."""
    ctrl = np.array([[0.0, 1.0], [1.5, 3.0], [4.0, 2.5], [5.0, -0.5]])
    return [(ctrl, 0.0), (ctrl, 1.0)]


CUTS: dict[str, Dataset[list[Cut]]] = {
    "3d-curve": Dataset(_split_space, tolerance=LOW_TOL, reason=LOW_REASON),
    "high-degree-40": Dataset(_split_40, tolerance=HIGH_TOL,
                              reason="n levels of rounding, as for the points"),
    "random-unseen": Dataset(_split_random, points=2, tolerance=LOW_TOL, reason=LOW_REASON),
    "line": Dataset(_split_line, tolerance=LOW_TOL, reason=LOW_REASON),
    "degree-0": Dataset(_split_degree_0, tolerance=LOW_TOL, reason=LOW_REASON),
    "ends": Dataset(_split_ends, tolerance=LOW_TOL, reason=LOW_REASON),
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


@over_datasets(CUTS)
def test_split_bezier(student: Student, credit: Credit, rng: np.random.Generator,
                      name: str, feedback: Feedback) -> None:
    data = CUTS[name]
    broken = fb.CONVENTIONS.record()
    for ctrl, t in data.build(rng):
        fb.grade_split(student, ctrl, t, oracle_split(ctrl, t),
                       atol=data.tol * fb.size(ctrl), broken=broken,
                       picture=feedback.image)
    broken.finish(credit)
