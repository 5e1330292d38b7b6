"""Hidden checks for the interpolation assignment: the real grading.

Nodes and weights are compared with ``reference``; weights at
any common scale (only ratios matter), including degrees where binomials and
factorials overflow. ``lagrange_interp`` is called with weights at odd scales
(the lecture's raw binomials, the reference times 3.7, a sign flip), several
functions and node sets (equispaced, Chebyshev, random nodes in any order, an
interval other than [-1, 1]), and judged against the reference, itself
cross-checked with ``scipy.interpolate.barycentric_interpolate``. At the nodes
the answer must be the data bit for bit; right next to a node it must be
finite. ``plot_runge`` is judged by the data of its curves.

Datasets named ``unseen-*`` draw their degree and points from the ``rng``
fixture (a regrade draws the same, another submission draws others), with
degrees that the notebook never mentions.

Tolerance for values: Higham's forward bound for the second barycentric form
is, to first order, ``|p_computed - p| <= ((3n + 4) + (3n + 2)) u Lambda_n max|f|``
with ``u = 2**-53`` and ``Lambda_n`` the Lebesgue constant of the nodes, that
is at most ``2 (3n + 4) u Lambda_n max|f|``. The student's program and the
reference may each be that far off, so the check allows ``SLACK = 10`` times
``(3n + 4) u Lambda_n max|f|`` (and never less than ``1e-14 max|f|``).

References
----------
J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange interpolation",
SIAM Review 46(3), 501-517, 2004. doi:10.1137/S0036144502417715
N. J. Higham, "The numerical stability of barycentric Lagrange interpolation",
IMA Journal of Numerical Analysis 24(4), 547-556, 2004. doi:10.1093/imanum/24.4.547
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.interpolate import barycentric_interpolate as scipy_barycentric

import interp_feedback as fb  # checks/public/interp_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Dataset, Feedback, Student, expect_array, over_datasets
from reference import (
    barycentric_interpolate,
    barycentric_weights,
    chebyshev_nodes,
    chebyshev_weights,
    equispaced_nodes,
    equispaced_weights,
    lebesgue_constant,
)

U = 2.0**-53
SLACK = 10.0

#: Every integer that interpolation.ipynb or the public checks write (degrees, sizes,
#: and numbers that only look like them): unseen degrees avoid all of them.
#: Keep in sync when the notebook changes.
MENTIONED = frozenset(range(17)) | frozenset({
    20, 24, 25, 30, 40, 46, 50, 53, 58, 64, 67, 100, 170, 171, 200, 201, 308, 323,
    549, 550, 551, 1001, 1030, 1100})


def unseen_degree(rng: np.random.Generator, low: int, high: int, *, odd: bool = False) -> int:
    """A degree or size in [low, high] that the notebook never mentions (odd only, if asked)."""
    choices = [n for n in range(low, high + 1)
               if n not in MENTIONED and (n % 2 == 1 or not odd)]
    return int(rng.choice(choices))


def tolerance(x: np.ndarray, f: np.ndarray) -> float:
    """SLACK times Higham's forward error bound for these nodes and data."""
    lam = lebesgue_constant(x)
    top = float(np.max(np.abs(f)))
    return max(SLACK * (3 * x.size + 1) * U * lam * top, 1e-14 * top)


# ---------------------------------------------------------------------------
# nodes
# ---------------------------------------------------------------------------

NODE_FAMILIES = {
    "equispaced": (equispaced_nodes, "equispaced nodes", lambda n: {}),
    "chebyshev": (chebyshev_nodes, "Chebyshev nodes",
                  lambda n: {fb.FIRST_KIND: chebyshev_nodes(n, kind=1)}),
}

#: name -> degree (from the rng for unseen); tolerance: NODE_ATOL of interp_feedback.py
NODE_DEGREES: dict[str, Dataset[int]] = {
    "degree-1": Dataset(lambda rng: 1),
    "unseen": Dataset(lambda rng: unseen_degree(rng, 5, 99)),
    "large-1000": Dataset(lambda rng: 1000),
}


@pytest.mark.points(1)
@pytest.mark.parametrize("degree", list(NODE_DEGREES))
@pytest.mark.parametrize("family", list(NODE_FAMILIES))
def test_nodes(student: Student, credit: Credit, rng: np.random.Generator, family: str,
               degree: str) -> None:
    make, what, known = NODE_FAMILIES[family]
    n = NODE_DEGREES[degree].build(rng)
    name = f"{family}_nodes"
    got = getattr(student, name)(n)
    fb.judge_nodes(got, make(n), call=f"{name}({n})", what=what, credit=credit,
                   known=known(n))


# ---------------------------------------------------------------------------
# weights
# ---------------------------------------------------------------------------

#: name -> (family, degree); tolerances: WEIGHT_RTOL and WEIGHT_ATOL of interp_feedback.py
WEIGHT_CASES: dict[str, Dataset[tuple[str, int]]] = {
    "equispaced-degree-1": Dataset(lambda rng: ("equispaced", 1)),
    "equispaced-unseen": Dataset(lambda rng: ("equispaced", unseen_degree(rng, 5, 60))),
    # 200! (about 7.9e374) overflows: factorial formulas give inf / inf = nan
    "equispaced-factorials-overflow-200": Dataset(lambda rng: ("equispaced", 200), points=2),
    # C(1100, 550) (about 3.3e329) overflows: raw binomials give inf or raise
    "equispaced-binomials-overflow-1100": Dataset(lambda rng: ("equispaced", 1100), points=2),
    # 2**1500 overflows and 2**-1500 underflows: scaling by 2**n fails both ways
    "equispaced-underflow-1500": Dataset(lambda rng: ("equispaced", 1500)),
    "chebyshev-degree-1": Dataset(lambda rng: ("chebyshev", 1)),
    "chebyshev-unseen": Dataset(lambda rng: ("chebyshev", unseen_degree(rng, 5, 500))),
    "chebyshev-large-5000": Dataset(lambda rng: ("chebyshev", 5000)),
}

WEIGHT_FAMILIES = {
    "equispaced": (equispaced_weights, fb.EQUISPACED_HINT,
                   lambda n: {fb.CHEBYSHEV_FOR_EQUISPACED: fb.alternating(n)} if n > 2 else {}),
    "chebyshev": (chebyshev_weights, fb.CHEBYSHEV_HINT,
                  lambda n: {fb.NOT_HALVED: fb.alternating(n)}),
}


@over_datasets(WEIGHT_CASES, "case")
def test_weights(student: Student, rng: np.random.Generator, case: str) -> None:
    family, n = WEIGHT_CASES[case].build(rng)
    make, hint, known = WEIGHT_FAMILIES[family]
    name = f"{family}_weights"
    call = f"{name}({n})"
    got = fb.call_weights(getattr(student, name), n, call=call, hint=hint)
    fb.judge_weights(got, make(n), call=call, n=n, hint=hint, known=known(n))


# ---------------------------------------------------------------------------
# values of the interpolant
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    """Nodes, weights (at the scale the student receives them), data and points."""

    x: np.ndarray
    w: np.ndarray
    f: np.ndarray
    t: np.ndarray
    about: str

    def expected(self) -> np.ndarray:
        value = barycentric_interpolate(self.x, self.f, self.t, self.w)
        theirs = scipy_barycentric(self.x, self.f, self.t)
        if np.max(np.abs(value - theirs)) > self.tol():
            raise RuntimeError("reference and scipy.interpolate disagree on "
                               f"{self.about}: fix the oracle.")
        return value

    def tol(self) -> float:
        return tolerance(self.x, self.f)


def _lecture_runge(rng: np.random.Generator) -> Problem:
    n = 15
    x = equispaced_nodes(n)
    w = np.array([(-1) ** j * math.comb(n, j) for j in range(n + 1)], dtype=float)
    return Problem(x, w, fb.runge(x), rng.uniform(-1, 1, 257),
                   "Runge's function in 16 equispaced nodes, the lecture's weights (-1)^j C(15, j)")


def _scaled_chebyshev(rng: np.random.Generator) -> Problem:
    n = 25
    x = chebyshev_nodes(n)
    return Problem(x, 3.7 * chebyshev_weights(n), fb.runge(x), rng.uniform(-1, 1, 400),
                   "Runge's function in 26 Chebyshev points, weights 3.7 (-1)^j, halved at "
                   "the ends")


def _large_chebyshev(rng: np.random.Generator) -> Problem:
    n = 300
    x = chebyshev_nodes(n)
    return Problem(x, 1e-7 * chebyshev_weights(n), np.exp(x) * np.sin(5 * x),
                   rng.uniform(-1, 1, 500), "exp(x) sin(5x) in 301 Chebyshev points")


def _cubic(s: np.ndarray) -> np.ndarray:
    return 2 * s**3 - s + 0.5


def _random_nodes(rng: np.random.Generator) -> Problem:
    """12 random nodes, at least 0.03 apart, in random order; a cubic is reproduced."""
    while True:
        x = rng.uniform(-1, 1, 12)
        if np.min(np.diff(np.sort(x))) > 0.03:
            break
    t = rng.uniform(x.min(), x.max(), 300)
    return Problem(x, -barycentric_weights(x), _cubic(x), t,
                   "a cubic in 12 random nodes, not sorted, weights with the opposite sign")


def _unseen_abs(rng: np.random.Generator) -> Problem:
    n = unseen_degree(rng, 41, 199)
    x = chebyshev_nodes(n)
    t = rng.uniform(-1, 1, unseen_degree(rng, 90, 400))
    return Problem(x, chebyshev_weights(n), np.abs(x), t, f"|x| in {n + 1} Chebyshev points")


def _unseen_equispaced(rng: np.random.Generator) -> Problem:
    n = unseen_degree(rng, 5, 28)
    x = equispaced_nodes(n)
    return Problem(x, equispaced_weights(n) * 2.0**-20, fb.runge(x),
                   rng.uniform(-1, 1, unseen_degree(rng, 60, 300)),
                   f"Runge's function in {n + 1} equispaced nodes")


def _other_interval(rng: np.random.Generator) -> Problem:
    n = 30
    x = 5.0 + 5.0 * chebyshev_nodes(n)
    return Problem(x, chebyshev_weights(n), np.sqrt(1.0 + x), rng.uniform(0, 10, 200),
                   "sqrt(1 + x) in 31 Chebyshev points of [0, 10]")


#: the tolerance of each problem is Higham's bound for its nodes and data: Problem.tol
VALUE_CASES: dict[str, Dataset[Problem]] = {
    "runge-equispaced-lecture-weights": Dataset(_lecture_runge, points=2),
    "runge-chebyshev-scaled-weights": Dataset(_scaled_chebyshev, points=2),
    "smooth-chebyshev-301-nodes": Dataset(_large_chebyshev, points=2),
    "cubic-random-unsorted-nodes": Dataset(_random_nodes, points=2),
    "unseen-abs-chebyshev": Dataset(_unseen_abs, points=2),
    "unseen-runge-equispaced": Dataset(_unseen_equispaced, points=2),
    "sqrt-chebyshev-on-0-10": Dataset(_other_interval, points=2),
}


@over_datasets(VALUE_CASES, "case")
def test_interp(student: Student, credit: Credit, rng: np.random.Generator, case: str) -> None:
    p = VALUE_CASES[case].build(rng)
    got = student.lagrange_interp(p.f, p.x, p.w, p.t)
    fb.judge_values(got, p.expected(), t=p.t, nodes=p.x, tol=p.tol(), credit=credit,
                    call=f"lagrange_interp ({p.about})")


# ---------------------------------------------------------------------------
# shapes: scalar in, scalar out; array in, array of the same shape out
# ---------------------------------------------------------------------------

#: the points t of each shape
SHAPES: dict[str, Dataset[float | np.ndarray]] = {
    "scalar": Dataset(lambda rng: 0.3),
    "one-point-array": Dataset(lambda rng: np.array([0.3])),
    "matrix": Dataset(lambda rng: rng.uniform(-1, 1, (6, 7))),
}


@over_datasets(SHAPES, "shape")
def test_interp_shapes(student: Student, credit: Credit, rng: np.random.Generator,
                       shape: str) -> None:
    n = 8
    x, w = chebyshev_nodes(n), chebyshev_weights(n)
    t = SHAPES[shape].build(rng)
    got = student.lagrange_interp(fb.runge(x), x, w, t)
    call = f"lagrange_interp(f, x, w, t) with t of shape {np.shape(t)}"
    if np.ndim(t) == 0:
        got = fb.judge_scalar(got, call=call, credit=credit)
    fb.judge_values(got, barycentric_interpolate(x, fb.runge(x), t, w), t=np.asarray(t),
                    nodes=x, tol=tolerance(x, fb.runge(x)), credit=credit, call=call)


# ---------------------------------------------------------------------------
# at and next to the nodes
# ---------------------------------------------------------------------------


@pytest.mark.points(2)
def test_exact_at_all_nodes(student: Student, rng: np.random.Generator) -> None:
    n = unseen_degree(rng, 5, 60)
    x = equispaced_nodes(n)
    f = fb.not_runge(x, rng)  # not Runge's function: a lagrange_interp ignoring fvals fails
    order = rng.permutation(n + 1)
    got = student.lagrange_interp(f, x, 1000.0 * equispaced_weights(n), x[order])
    fb.judge_exact(got, f, x, order, call=f"lagrange_interp(f, x, w, t=x) with {n + 1} "
                                          "equispaced nodes (shuffled)")


@pytest.mark.points(1)
def test_exact_at_each_node_scalar(student: Student, rng: np.random.Generator) -> None:
    n = 300
    x, w = chebyshev_nodes(n), chebyshev_weights(n)
    f = np.exp(x) * np.cos(3 * x)
    for j in [0, n, *rng.choice(np.arange(1, n), 6, replace=False)]:
        got = student.lagrange_interp(f, x, w, float(x[j]))
        fb.judge_exact(got, f, x, np.array(j), call=f"lagrange_interp(f, x, w, t=x[{j}])")


@pytest.mark.points(1)
def test_nodes_among_points(student: Student, credit: Credit,
                            rng: np.random.Generator) -> None:
    n = unseen_degree(rng, 21, 60)
    x, w = chebyshev_nodes(n), chebyshev_weights(n)
    f = np.tanh(3 * x)
    picked = rng.choice(n + 1, 5, replace=False)
    t = rng.uniform(-1, 1, 40)
    spots = rng.choice(40, 5, replace=False)
    t[spots] = x[picked]
    got = student.lagrange_interp(f, x, w, t)
    call = f"lagrange_interp(f, x, w, t) with {n + 1} Chebyshev points, some t on nodes"
    arr = expect_array(got, shape=t.shape, dtype_kind="iuf", name=call)
    fb.judge_exact(arr[spots], f, x, picked, call=call)
    fb.judge_values(arr, barycentric_interpolate(x, f, t, w), t=t, nodes=x,
                    tol=tolerance(x, f), credit=credit, call=call)


#: nodes x, weights w, data f, points t, and what they are
NearCase = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]


def _next_to_nodes(rng: np.random.Generator) -> NearCase:
    n = unseen_degree(rng, 21, 80, odd=True)  # odd: no node at 0 (that case is below)
    x = chebyshev_nodes(n)
    inner = x[1:-1]
    t = np.concatenate([np.nextafter(inner, np.inf), np.nextafter(inner, -np.inf),
                        [np.nextafter(-1.0, 0.0), np.nextafter(1.0, 0.0)]])
    return x, chebyshev_weights(n), np.cos(2 * x) + x, t, f"{n + 1} Chebyshev points"


def _next_to_zero(rng: np.random.Generator) -> NearCase:
    n = 16
    x = equispaced_nodes(n)  # node 8 is exactly 0
    # two ordinary points (not nodes) besides: values next to 0 alone are all about f(0),
    # so any constant would be "a common factor times the interpolant"
    t = np.array([5e-324, -5e-324, 2.5e-320, 1e-310, -3e-308, 0.3, -0.7])
    # not Runge's function: p(0) must be the sample there, not a memorised 1
    return x, equispaced_weights(n), fb.not_runge(x, rng), t, ("17 equispaced nodes, t next "
                                                               "to the node 0")


NEAR: dict[str, Dataset[NearCase]] = {
    "next-to-nodes": Dataset(_next_to_nodes, points=2),
    "next-to-zero-subnormal": Dataset(_next_to_zero),
}


@over_datasets(NEAR, "case")
def test_near_nodes(student: Student, credit: Credit, rng: np.random.Generator,
                    case: str) -> None:
    x, w, f, t, about = NEAR[case].build(rng)
    got = student.lagrange_interp(f, x, w, t)
    fb.judge_values(got, barycentric_interpolate(x, f, t, w), t=t, nodes=x,
                    tol=tolerance(x, f), credit=credit,
                    call=f"lagrange_interp ({about}, one double away from a node)")


# ---------------------------------------------------------------------------
# the Runge plot
# ---------------------------------------------------------------------------


def _interpolant(family: str, m: int) -> Callable[[np.ndarray], np.ndarray]:
    nodes, weights = {"equispaced": (equispaced_nodes, equispaced_weights),
                      "Chebyshev": (chebyshev_nodes, chebyshev_weights)}[family]
    x, w = nodes(m), weights(m)
    return lambda s: barycentric_interpolate(x, fb.runge(x), s, w)


#: the degree n of each plot; curves are found within CURVE_RTOL of interp_feedback.py
PLOTS: dict[str, Dataset[int]] = {
    "degree-12": Dataset(lambda rng: 12, points=3),
    "unseen": Dataset(lambda rng: unseen_degree(rng, 6, 30), points=2),
}


@over_datasets(PLOTS, "case")
def test_plot_runge(student: Student, credit: Credit, feedback: Feedback,
                    rng: np.random.Generator, case: str) -> None:
    fb.grade_runge_plot(student, feedback, credit, PLOTS[case].build(rng), _interpolant)
