"""Tests of :mod:`reference.bezier` against SciPy's BPoly and exact properties."""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BPoly
from scipy.stats import binom

from reference import bernstein, bezier, de_casteljau, split

# `reference.bezier` is the function after `import reference` (it is
# re-exported by the package): reach the module itself through importlib.
bez = importlib.import_module("reference._bezier")

# The lecture's demos (quad_demo at t = 0.4, cubic_demo at t = 0.7).
QUAD = np.array([[0.0, 0.0], [1.0, 1.0], [1.2, 0.4]])
CUBIC = np.array([[0.0, 0.0], [4.0, 1.0], [9.0, 1.0], [3.0, 4.0]])


def bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


def bpoly(ctrl):
    """SciPy's Bernstein-form piecewise polynomial on the single piece [0, 1]."""
    return BPoly(np.asarray(ctrl, float)[:, None, :], [0.0, 1.0])


def random_ctrl(seed, degree, dim):
    return np.random.default_rng(seed).normal(size=(degree + 1, dim))


# --------------------------------------------------------------------------
# bernstein
# --------------------------------------------------------------------------


@pytest.mark.parametrize("n", [0, 1, 2, 5, 20, 100, 1029, 1030, 2000])
def test_bernstein_matches_the_binomial_pmf(n):
    # B_{i,n}(t) is the binomial probability of i successes in n trials.
    t = np.array([0.0, 1e-3, 0.1, 0.25, 0.5, 0.7, 0.999, 1.0])
    i = np.arange(n + 1)
    ours = np.array([bernstein(n, k, t) for k in i])
    pmf = binom.pmf(i[:, None], n, t)
    assert np.all((ours == 0) == (pmf == 0))  # same underflow pattern
    nonzero = pmf > 0
    assert np.allclose(ours[nonzero], pmf[nonzero], rtol=2e-12, atol=0)


def test_bernstein_small_cases_exact():
    assert bernstein(3, 1, [0.0, 0.5, 1.0]).tolist() == [0.0, 0.375, 0.0]
    assert bernstein(0, 0, 0.3) == 1.0
    assert bernstein(4, 0, 0.0) == 1.0 and bernstein(4, 4, 1.0) == 1.0
    value = bernstein(2, 1, 0.5)
    assert isinstance(value, np.float64) and value == 0.5
    assert bernstein(3, 2, np.full((2, 3), 0.5)).shape == (2, 3)
    # Outside [0, 1] the polynomial is extended: B_{1,3}(-1) = 3 (-1) 2**2.
    assert bernstein(3, 1, -1.0) == -12.0


@settings(max_examples=80, deadline=None)
@given(
    n=st.integers(0, 60),
    t=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
)
def test_bernstein_partition_of_unity_and_nonnegativity(n, t):
    t = np.array(t)
    basis = np.array([bernstein(n, i, t) for i in range(n + 1)])
    assert np.all(basis >= 0)
    assert np.allclose(basis.sum(axis=0), 1.0, rtol=0, atol=(n + 1) * 4e-16)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(0, 30), t=st.floats(-3.0, 3.0))
def test_bernstein_partition_of_unity_extends_outside(n, t):
    total = math.fsum(float(bernstein(n, i, t)) for i in range(n + 1))
    scale = (abs(t) + abs(1 - t)) ** n  # the sum of |terms|
    assert abs(total - 1.0) <= 1e-14 * scale


@pytest.mark.parametrize(
    "args, match",
    [
        ((3, 4, 0.5), r"`i` must satisfy 0 <= i <= n = 3; got 4"),
        ((3, -1, 0.5), r"`i` must be >= 0"),
        ((-1, 0, 0.5), r"`n` must be >= 0"),
        ((2.0, 1, 0.5), r"`n` must be an integer"),
        ((2, 1.0, 0.5), r"`i` must be an integer"),
        ((2, 1, np.nan), r"`t` must contain only finite"),
    ],
)
def test_bernstein_validates(args, match):
    with pytest.raises(ValueError, match=match):
        bernstein(*args)


# --------------------------------------------------------------------------
# bezier
# --------------------------------------------------------------------------


@pytest.mark.parametrize("degree", [0, 1, 2, 3, 5, 8, 15])
@pytest.mark.parametrize("dim", [1, 2, 3])
def test_bezier_matches_bpoly(degree, dim):
    ctrl = random_ctrl(100 * degree + dim, degree, dim)
    t = np.random.default_rng(degree).uniform(0, 1, 300)
    assert np.allclose(bezier(ctrl, t), bpoly(ctrl)(t), rtol=0, atol=1e-14 * (degree + 1))


def test_bezier_extrapolates_like_bpoly():
    ctrl = random_ctrl(1, 4, 2)
    t = np.linspace(-1.5, 2.5, 41)
    assert np.allclose(bezier(ctrl, t), bpoly(ctrl)(t), rtol=1e-12, atol=1e-12)


def test_bezier_matches_the_bernstein_sum_and_the_lecture():
    t = np.linspace(0, 1, 31)
    for ctrl in (QUAD, CUBIC):
        n = len(ctrl) - 1
        explicit = sum(bernstein(n, i, t)[:, None] * ctrl[i] for i in range(n + 1))
        assert np.allclose(bezier(ctrl, t), explicit, rtol=0, atol=1e-14)
    # quad_demo: ptC = ptA + t (ptB - ptA) with ptA, ptB on the polygon legs.
    t0 = 0.4
    pt_a = QUAD[0] + t0 * (QUAD[1] - QUAD[0])
    pt_b = QUAD[1] + t0 * (QUAD[2] - QUAD[1])
    assert np.allclose(bezier(QUAD, t0), pt_a + t0 * (pt_b - pt_a), rtol=0, atol=1e-15)


@pytest.mark.parametrize("seed", range(5))
def test_bezier_end_points_are_exact(seed):
    ctrl = random_ctrl(seed, 2 + seed, 2)
    ends = bezier(ctrl, [0.0, 1.0])
    assert np.array_equal(bits(ends[0]), bits(ctrl[0]))
    assert np.array_equal(bits(ends[1]), bits(ctrl[-1]))


def test_bezier_shapes_and_chunking(monkeypatch):
    assert bezier(CUBIC, 0.3).shape == (2,)
    assert bezier(CUBIC, [0.3]).shape == (1, 2)
    assert bezier(CUBIC, np.linspace(0, 1, 7)).shape == (7, 2)
    assert bezier(CUBIC, []).shape == (0, 2)
    assert bezier([[1.0, 2.0, 3.0]], [0.2, 0.9]).tolist() == [[1.0, 2.0, 3.0]] * 2
    t = np.random.default_rng(5).uniform(0, 1, 1000)
    whole = bezier(CUBIC, t)
    monkeypatch.setattr(bez, "_CHUNK_POINTS", 13)
    assert np.array_equal(bezier(CUBIC, t), whole)  # elementwise: identical


@pytest.mark.parametrize(
    "args, match",
    [
        (([0.0, 1.0, 2.0], 0.5), r"`ctrl` must have shape \(n, d\)"),
        ((np.zeros((0, 2)), 0.5), r"`ctrl` must hold at least 1 point"),
        (([[0.0, np.inf]], 0.5), r"`ctrl` must contain only finite"),
        ((CUBIC, [[0.5]]), r"`t` must be a scalar or 1-D array"),
        ((CUBIC, np.nan), r"`t` must contain only finite"),
    ],
)
def test_bezier_validates(args, match):
    with pytest.raises(ValueError, match=match):
        bezier(*args)


@settings(max_examples=50, deadline=None)
@given(
    degree=st.integers(0, 12),
    dim=st.integers(1, 3),
    seed=st.integers(0, 2**32 - 1),
    t=st.floats(0.0, 1.0),
)
def test_bezier_lies_in_the_convex_hull_bounding_box(degree, dim, seed, t):
    ctrl = random_ctrl(seed, degree, dim)
    point = bezier(ctrl, t)
    slack = 1e-14 * (degree + 1) * np.max(np.abs(ctrl))
    assert np.all(point >= ctrl.min(axis=0) - slack)
    assert np.all(point <= ctrl.max(axis=0) + slack)


# --------------------------------------------------------------------------
# de_casteljau and split
# --------------------------------------------------------------------------


def test_de_casteljau_levels_reproduce_the_cubic_demo():
    t = 0.7
    levels = de_casteljau(CUBIC, t)
    assert [level.shape for level in levels] == [(4, 2), (3, 2), (2, 2), (1, 2)]
    p = CUBIC
    pt_a, pt_b, pt_c = (p[k] + t * (p[k + 1] - p[k]) for k in range(3))
    pt_d, pt_e = pt_a + t * (pt_b - pt_a), pt_b + t * (pt_c - pt_b)
    pt_f = pt_d + t * (pt_e - pt_d)
    assert np.allclose(levels[1], [pt_a, pt_b, pt_c], atol=1e-14)
    assert np.allclose(levels[2], [pt_d, pt_e], atol=1e-14)
    assert np.allclose(levels[3], [pt_f], atol=1e-14)
    assert np.array_equal(levels[0], CUBIC)
    levels[0][0, 0] = 99.0  # a copy: the caller's array is untouched
    assert CUBIC[0, 0] == 0.0


@pytest.mark.parametrize("t", [0.0, 0.1, 0.37, 0.5, 0.99, 1.0, -0.5, 1.7])
def test_de_casteljau_last_level_is_bezier_bit_for_bit(t):
    ctrl = random_ctrl(9, 6, 3)
    assert np.array_equal(bits(de_casteljau(ctrl, t)[-1][0]), bits(bezier(ctrl, t)))
    assert np.array_equal(bits(de_casteljau(ctrl, t)[-1][0]), bits(bezier(ctrl, [t])[0]))


def test_de_casteljau_and_split_validate_t():
    for call in (de_casteljau, split):
        with pytest.raises(ValueError, match=r"`t` must be a single number"):
            call(CUBIC, [0.5, 0.6])
        with pytest.raises(ValueError, match=r"`t` must contain only finite"):
            call(CUBIC, np.inf)
        with pytest.raises(ValueError, match=r"`ctrl` must have shape"):
            call([1.0, 2.0], 0.5)


@pytest.mark.parametrize("t", [0.5, 0.25, 0.8, 1e-3])
@pytest.mark.parametrize("degree", [1, 3, 7])
def test_split_reproduces_the_curve_on_both_halves(t, degree):
    ctrl = random_ctrl(degree, degree, 2)
    left, right = split(ctrl, t)
    assert left.shape == right.shape == ctrl.shape
    u = np.linspace(0, 1, 101)
    scale = 1e-14 * (degree + 1) * np.max(np.abs(ctrl))
    assert np.allclose(bezier(left, u), bezier(ctrl, t * u), rtol=0, atol=scale)
    assert np.allclose(bezier(right, u), bezier(ctrl, t + (1 - t) * u), rtol=0, atol=scale)
    assert np.array_equal(left[0], ctrl[0]) and np.array_equal(right[-1], ctrl[-1])
    assert np.array_equal(left[-1], right[0])
    assert np.array_equal(left[-1], bezier(ctrl, t))


def test_split_matches_bpoly_on_the_halves():
    ctrl = random_ctrl(2, 5, 3)
    left, right = split(ctrl, 0.5)
    u = np.linspace(0, 1, 51)
    assert np.allclose(bpoly(left)(u), bpoly(ctrl)(u / 2), atol=1e-14)
    assert np.allclose(bpoly(right)(u), bpoly(ctrl)(0.5 + u / 2), atol=1e-14)


def test_split_at_the_ends_and_degree_zero():
    left, right = split(QUAD, 0.0)
    assert np.allclose(left, QUAD[[0, 0, 0]]) and np.array_equal(right, QUAD)
    left, right = split(QUAD, 1.0)
    assert np.array_equal(left, QUAD) and np.allclose(right, QUAD[[2, 2, 2]])
    left, right = split([[1.0, 2.0]], 0.3)
    assert left.tolist() == right.tolist() == [[1.0, 2.0]]


def test_repeated_midpoint_subdivision_converges_to_the_curve():
    ctrl = CUBIC
    polygons = [ctrl]
    for _ in range(6):
        polygons = [half for poly in polygons for half in split(poly, 0.5)]
    # Each control point of the 64 small polygons is within O(4**-k) of the curve.
    params = np.linspace(0, 1, len(polygons) + 1)
    for poly, (a, b) in zip(polygons, zip(params[:-1], params[1:])):
        on_curve = bezier(ctrl, np.linspace(a, b, len(poly)))
        assert np.max(np.abs(poly - on_curve)) < 5e-3


# --------------------------------------------------------------------------
# Documentation
# --------------------------------------------------------------------------
