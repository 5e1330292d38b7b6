"""Tests of the interpolation part of :mod:`reference` against SciPy, exact arithmetic and theory."""

from __future__ import annotations

import importlib
import math
import sys
import tracemalloc
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.interpolate import BarycentricInterpolator
from scipy.interpolate import barycentric_interpolate as scipy_barycentric

from reference import (
    barycentric_interpolate,
    barycentric_weights,
    chebyshev_nodes,
    chebyshev_weights,
    equispaced_nodes,
    equispaced_weights,
    lebesgue_constant,
)

barycentric_module = importlib.import_module("reference._barycentric")
lebesgue_module = importlib.import_module("reference._lebesgue")
TINY = sys.float_info.min


def runge(x):
    return 1.0 / (1.0 + 16.0 * x**2)


def bits(a):
    return np.asarray(a, dtype=np.float64).view(np.int64)


# Node sets used by several tests; tolerances live beside the comparisons.
NODE_SETS = {
    "chebyshev2-20": chebyshev_nodes(20),
    "chebyshev1-21": chebyshev_nodes(21, kind=1),
    "equispaced-12": equispaced_nodes(12),
    "jittered-chebyshev-30": np.sort(
        chebyshev_nodes(30) + np.random.default_rng(3).uniform(-0.01, 0.01, 31)
    ),
    "shifted-scaled": 1e3 + 50.0 * chebyshev_nodes(15),
    "unsorted": np.random.default_rng(4).permutation(chebyshev_nodes(10)),
}


# --------------------------------------------------------------------------
# Nodes
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "make",
    [equispaced_nodes, chebyshev_nodes, lambda n: chebyshev_nodes(n, kind=1)],
    ids=["equispaced", "chebyshev2", "chebyshev1"],
)
@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 10, 64, 101, 1000])
def test_nodes_are_ascending_symmetric_in_range(make, n):
    x = make(n)
    assert x.shape == (n + 1,) and x.dtype == np.float64
    assert np.all(np.diff(x) > 0)
    assert np.array_equal(x, -x[::-1])
    assert np.all(np.abs(x) <= 1.0)
    if n % 2 == 0:
        assert bits(x[n // 2]) == 0  # +0.0, not -6e-17


@pytest.mark.parametrize("n", [1, 2, 5, 16, 333])
def test_node_formulas(n):
    j = np.arange(n + 1)
    assert np.allclose(equispaced_nodes(n), -1 + 2 * j / n, rtol=0, atol=1e-15)
    assert np.allclose(chebyshev_nodes(n), -np.cos(j * np.pi / n), rtol=0, atol=1e-15)
    assert np.allclose(
        chebyshev_nodes(n, kind=1), -np.cos((2 * j + 1) * np.pi / (2 * n + 2)), rtol=0, atol=1e-15
    )
    assert chebyshev_nodes(n)[0] == -1.0 and chebyshev_nodes(n)[-1] == 1.0
    assert equispaced_nodes(n)[0] == -1.0 and equispaced_nodes(n)[-1] == 1.0


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: equispaced_nodes(0), r"`n` must be >= 1"),
        (lambda: chebyshev_nodes(0), r"`n` must be >= 1"),
        (lambda: equispaced_weights(-3), r"`n` must be >= 1"),
        (lambda: equispaced_nodes(2.0), r"`n` must be an integer"),
        (lambda: chebyshev_nodes(True), r"`n` must be an integer"),
        (lambda: chebyshev_nodes(4, kind=3), r"`kind` must be 1 .* or 2"),
        (lambda: chebyshev_weights(4, kind="2"), r"`kind` must be 1"),
        (lambda: chebyshev_weights(4, kind=True), r"`kind` must be 1"),
    ],
)
def test_node_and_weight_arguments_are_validated(call, match):
    with pytest.raises(ValueError, match=match):
        call()


# --------------------------------------------------------------------------
# Weights
# --------------------------------------------------------------------------


def test_equispaced_weights_are_the_exact_ratios_correctly_rounded():
    n = 200
    middle = math.comb(n, n // 2)
    exact = [(-1) ** j * Fraction(math.comb(n, j), middle) for j in range(n + 1)]
    expected = np.array([float(f) for f in exact])
    assert np.array_equal(bits(equispaced_weights(n)), bits(expected))


@pytest.mark.parametrize("n", [1, 2, 3, 8, 9])
def test_equispaced_weights_small(n):
    w = equispaced_weights(n)
    expected = np.array([(-1) ** j * math.comb(n, j) for j in range(n + 1)], float)
    assert np.allclose(w, expected / math.comb(n, n // 2), rtol=1e-15, atol=0)
    assert np.max(np.abs(w)) == 1.0


@pytest.mark.parametrize("n", [200, 1000, 1027, 1028, 3000, 5000])
def test_equispaced_weights_large_n_finite_nonzero_alternating(n):
    w = equispaced_weights(n)
    assert np.all(np.isfinite(w)) and np.all(w != 0)
    assert np.all(np.abs(w) >= TINY)  # normal numbers, no subnormals
    assert np.array_equal(np.sign(w), (-1.0) ** np.arange(n + 1))
    assert np.max(np.abs(w)) == 1.0
    assert np.array_equal(np.abs(w), np.abs(w[::-1]))
    if n <= 1027:  # every ratio is a normal number: none clamped
        assert np.min(np.abs(w)) > TINY
        j = 3  # spot check against exact arithmetic
        assert abs(w[j]) == float(Fraction(math.comb(n, j), math.comb(n, n // 2)))
    else:  # the outermost ratios underflow and are clamped
        assert np.min(np.abs(w)) == TINY


@pytest.mark.parametrize("n", [1, 2, 5, 10, 50, 200])
@pytest.mark.parametrize("kind", [1, 2])
def test_chebyshev_weights_match_the_product_formula(n, kind):
    w = chebyshev_weights(n, kind=kind)
    general = barycentric_weights(chebyshev_nodes(n, kind=kind))
    # Same up to the common scale. The nodes are rounded, and near +-1 they
    # are ~1/n**2 apart, so each difference carries a relative error up to
    # ~n**2 eps: the weights of the rounded nodes differ by ~1e-16 n**2.
    scale = np.max(np.abs(w))
    assert np.allclose(general * scale, w, rtol=1e-16 * n**2 + 2e-15, atol=0)


def test_chebyshev_weights_closed_forms():
    assert chebyshev_weights(4).tolist() == [0.5, -1.0, 1.0, -1.0, 0.5]
    assert chebyshev_weights(1).tolist() == [0.5, -0.5]
    n = 7
    j = np.arange(n + 1)
    w1 = chebyshev_weights(n, kind=1)
    assert np.allclose(w1, (-1.0) ** j * np.sin((2 * j + 1) * np.pi / (2 * n + 2)), atol=1e-16)
    assert np.array_equal(np.abs(w1), np.abs(w1[::-1]))


@pytest.mark.parametrize("n", [4, 30, 200])
def test_barycentric_weights_match_equispaced(n):
    assert np.allclose(
        barycentric_weights(equispaced_nodes(n)), equispaced_weights(n), rtol=1e-15 * n, atol=0
    )


@pytest.mark.parametrize("name", sorted(NODE_SETS))
def test_barycentric_weights_match_scipy(name):
    x = NODE_SETS[name]
    ours = barycentric_weights(x)
    theirs = BarycentricInterpolator(x, np.zeros_like(x)).wi
    k = np.argmax(np.abs(ours))
    theirs = theirs / theirs[k] * ours[k]
    assert np.allclose(ours, theirs, rtol=1e-12, atol=0)
    assert np.max(np.abs(ours)) == 1.0
    assert ours[np.argmin(x)] > 0


def test_barycentric_weights_no_overflow_for_extreme_scales_and_many_nodes():
    base = barycentric_weights(chebyshev_nodes(40))
    for scale in (1e-200, 1e200):
        assert np.allclose(barycentric_weights(scale * chebyshev_nodes(40)), base, rtol=1e-13)
    # 3000 equispaced nodes: the products span ~2**3000, far beyond a double.
    w = barycentric_weights(equispaced_nodes(3000))
    assert np.all(np.isfinite(w)) and np.all(np.abs(w) >= TINY)
    assert np.array_equal(np.sign(w), (-1.0) ** np.arange(3001))


def test_barycentric_weights_single_node_and_errors():
    assert barycentric_weights([3.5]).tolist() == [1.0]
    with pytest.raises(ValueError, match=r"nodes\[1\] == nodes\[3\] == 0\.5"):
        barycentric_weights([0.0, 0.5, 1.0, 0.5])
    with pytest.raises(ValueError, match="at least one node"):
        barycentric_weights([])
    with pytest.raises(ValueError, match="`nodes` must be 1-dimensional"):
        barycentric_weights([[0.0, 1.0]])
    with pytest.raises(ValueError, match="`nodes` must contain only finite"):
        barycentric_weights([0.0, np.nan])


# --------------------------------------------------------------------------
# barycentric_interpolate
# --------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(8))
def test_interpolate_matches_scipy_random(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 25))
    x = np.sort(chebyshev_nodes(n) + rng.uniform(-0.2, 0.2, n + 1) / (n + 1))
    d = int(rng.integers(1, 4))
    y = rng.normal(size=(n + 1, d)) if seed % 2 else rng.normal(size=n + 1)
    t = rng.uniform(x[0], x[-1], 500)
    ours = barycentric_interpolate(x, y, t)
    theirs = scipy_barycentric(x, y, t)
    assert ours.shape == theirs.shape
    # Inside the interval both are forward stable (Lambda < 5 here).
    assert np.allclose(ours, theirs, rtol=0, atol=1e-13 * np.max(np.abs(y)))
    # Outside, the second form loses accuracy with the growth of the
    # polynomial (values up to ~1e6 at t = +-1.2): compare relatively.
    te = rng.uniform(-1.2, 1.2, 500)
    assert np.allclose(
        barycentric_interpolate(x, y, te), scipy_barycentric(x, y, te), rtol=1e-8, atol=1e-12
    )


def test_interpolate_matches_scipy_interpolator_with_given_weights():
    x = chebyshev_nodes(40, kind=1)
    y = np.exp(x) * np.sin(5 * x)
    t = np.linspace(-1, 1, 777)
    w = chebyshev_weights(40, kind=1)
    ours = barycentric_interpolate(x, y, t, weights=w)
    theirs = BarycentricInterpolator(x, y)(t)
    assert np.allclose(ours, theirs, rtol=0, atol=1e-13)
    assert np.allclose(ours, barycentric_interpolate(x, y, t), rtol=0, atol=1e-14)


@pytest.mark.parametrize("name", sorted(NODE_SETS))
def test_nodes_are_reproduced_bit_for_bit(name):
    x = NODE_SETS[name]
    rng = np.random.default_rng(7)
    y = rng.normal(size=x.size) * 10.0 ** rng.integers(-300, 300, x.size)
    y[0] = -0.0
    y[-1] = 5e-324
    assert np.array_equal(bits(barycentric_interpolate(x, y, x)), bits(y))
    for j in (0, x.size // 2, x.size - 1):
        value = barycentric_interpolate(x, y, x[j])
        assert isinstance(value, np.float64) and bits(value) == bits(y[j])
    yy = rng.normal(size=(x.size, 3))
    assert np.array_equal(bits(barycentric_interpolate(x, yy, x[::-1])), bits(yy[::-1]))


@pytest.mark.parametrize("name", sorted(NODE_SETS))
def test_points_next_to_nodes_are_finite_and_accurate(name):
    x = NODE_SETS[name]
    y = np.cos(3 * np.arange(x.size))
    for direction in (-np.inf, np.inf):
        t = np.nextafter(x, direction)
        p = barycentric_interpolate(x, y, t)
        assert np.all(np.isfinite(p))
        assert np.max(np.abs(p - y)) < 1e-9


def test_points_a_subnormal_distance_from_a_node_and_huge_weights():
    x = np.array([-1.0, -1e-300, 0.0, 1e-300, 1.0])
    y = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    for t in (5e-324, -5e-324, 1e-310, -0.0):
        p = barycentric_interpolate(x, y, t)
        assert np.isfinite(p) and abs(p - 3.0) < 1e-9
    # The lecture's raw binomial weights, up to C(60, 30) ~ 1.2e17.
    n = 60
    xe = equispaced_nodes(n)
    raw = np.array([(-1) ** j * math.comb(n, j) for j in range(n + 1)], float)
    p = barycentric_interpolate(xe, runge(xe), np.nextafter(xe, 2.0), weights=raw)
    assert np.all(np.isfinite(p)) and np.max(np.abs(p - runge(xe))) < 1e-5


def test_interpolate_shapes_and_types():
    x = chebyshev_nodes(5)
    y = x**2
    assert isinstance(barycentric_interpolate(x, y, 0.3), np.float64)
    assert barycentric_interpolate(x, y, [0.3]).shape == (1,)
    assert barycentric_interpolate(x, y, np.zeros((4, 3))).shape == (4, 3)
    assert barycentric_interpolate(x, y, []).shape == (0,)
    yy = np.c_[y, 2 * y]
    assert barycentric_interpolate(x, yy, 0.3).shape == (2,)
    assert barycentric_interpolate(x, yy, np.zeros((4, 3))).shape == (4, 3, 2)
    assert barycentric_interpolate([2.0], [7.0], [0.0, 5.0]).tolist() == [7.0, 7.0]


def test_chunking_gives_the_same_result(monkeypatch):
    rng = np.random.default_rng(11)
    x = chebyshev_nodes(30)
    y = rng.normal(size=(31, 2))
    t = np.concatenate([rng.uniform(-1, 1, 1000), x, np.nextafter(x, 0)])
    whole = barycentric_interpolate(x, y, t)
    monkeypatch.setattr(barycentric_module, "_CHUNK_POINTS", 7)
    chunked = barycentric_interpolate(x, y, t)
    # BLAS may sum in another order for another block size: rounding only.
    assert np.allclose(chunked, whole, rtol=1e-14, atol=1e-14)
    assert np.array_equal(chunked[1000:1031], y)


def test_memory_is_bounded_by_chunking():
    x = chebyshev_nodes(99)
    y = np.sin(x)
    t = np.linspace(-1, 1, 200_000)
    tracemalloc.start()
    try:
        barycentric_interpolate(x, y, t)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    full_matrix = t.size * x.size * 8  # 160 MB: what forming it at once costs
    assert peak < 12e6 < full_matrix / 10


@pytest.mark.parametrize(
    "args, match",
    [
        (([0.0, 1.0, 1.0], [1, 2, 3], 0.5), r"nodes\[1\] == nodes\[2\]"),
        (([0.0, 1.0, 2.0], [1, 2], 0.5), r"`values` must have shape \(3,\) or \(3, d\)"),
        (([0.0, 1.0, 2.0], np.ones((3, 2, 2)), 0.5), r"`values` must have shape"),
        (([0.0, 1.0, 2.0], [1, np.inf, 3], 0.5), r"`values` must contain only finite"),
        (([0.0, 1.0, 2.0], [1, 2, 3], np.nan), r"`t` must contain only finite"),
        (([0.0, 1.0, 2.0], [1, 2, 3], "a"), r"`t` must be an array of real numbers"),
        (([0.0, 1.0, 2.0], [1, 2, 3], 0.5, [1, 0, 1]), r"weights\[1\] == 0"),
        (([0.0, 1.0, 2.0], [1, 2, 3], 0.5, [1, 1]), r"`weights` must have one entry per node"),
    ],
)
def test_interpolate_arguments_are_validated(args, match):
    with pytest.raises(ValueError, match=match):
        barycentric_interpolate(*args)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(1, 30),
    kind=st.sampled_from([1, 2]),
    degree_offset=st.integers(0, 30),
    seed=st.integers(0, 2**32 - 1),
)
def test_polynomials_of_degree_at_most_n_are_reproduced(n, kind, degree_offset, seed):
    rng = np.random.default_rng(seed)
    degree = max(0, n - degree_offset)
    coef = rng.uniform(-1, 1, degree + 1)
    poly = np.polynomial.Chebyshev(coef)
    x = chebyshev_nodes(n, kind=kind)
    t = rng.uniform(-1, 1, 50)
    p = barycentric_interpolate(x, poly(x), t, weights=chebyshev_weights(n, kind=kind))
    # Chebyshev points: Lebesgue constant < 4, so the error is a few ulps
    # of sum |c_k| (the size of the data), times n for the sums.
    assert np.allclose(p, poly(t), rtol=0, atol=1e-14 * (n + 1) * np.sum(np.abs(coef)))


# --------------------------------------------------------------------------
# Runge's phenomenon, convergence, Lebesgue constants
# --------------------------------------------------------------------------


def test_runge_converges_geometrically_in_chebyshev_points():
    t = np.linspace(-1, 1, 5001)
    rho = 0.25 + math.sqrt(1 + 1 / 16)  # Bernstein ellipse through the poles +-i/4
    errors = {}
    for n in (10, 20, 40, 80, 160):
        x = chebyshev_nodes(n)
        errors[n] = np.max(np.abs(barycentric_interpolate(x, runge(x), t) - runge(t)))
    for n in (10, 20, 40, 80):
        assert errors[n] <= 2 * rho**-n  # the rate of the theory, with a constant <= 2
        assert errors[2 * n] < errors[n] / 2 or errors[2 * n] < 1e-14
    assert errors[160] < 1e-14


def test_runge_diverges_in_equispaced_points():
    t = np.linspace(-1, 1, 5001)
    errors = []
    for n in (10, 20, 30, 40):
        x = equispaced_nodes(n)
        errors.append(np.max(np.abs(barycentric_interpolate(x, runge(x), t) - runge(t))))
    assert errors[-1] > 100 and all(b > 10 * a for a, b in zip(errors, errors[1:]))


def brute_force_lebesgue(x, points=200_001):
    t = np.linspace(np.min(x), np.max(x), points)
    w = barycentric_weights(x)
    return np.max(lebesgue_module._lebesgue_function(x, w, t))


@pytest.mark.parametrize("name", sorted(NODE_SETS))
def test_lebesgue_constant_against_a_fine_grid(name):
    x = NODE_SETS[name]
    ours = lebesgue_constant(x)
    dense = brute_force_lebesgue(x)
    assert dense * (1 - 1e-12) <= ours <= dense * (1 + 1e-5)


def test_lebesgue_constant_exact_small_cases():
    assert lebesgue_constant([0.3]) == 1.0
    assert lebesgue_constant([-1.0, 1.0]) == pytest.approx(1.0, abs=1e-15)
    # Three equispaced nodes: max of |l0|+|l1|+|l2| is 5/4 at x = +-1/2.
    assert lebesgue_constant(equispaced_nodes(2)) == pytest.approx(1.25, rel=1e-14)
    # Tabulated values (40-digit arithmetic) for equispaced nodes.
    assert lebesgue_constant(equispaced_nodes(20)) == pytest.approx(10986.705892672847, rel=1e-10)
    assert lebesgue_constant(equispaced_nodes(40)) == pytest.approx(4692451395.306966, rel=1e-6)


def test_lebesgue_constant_grows_exponentially_for_equispaced_nodes():
    ns = np.arange(5, 41, 5)
    lam = np.array([lebesgue_constant(equispaced_nodes(n)) for n in ns])
    # Bounds of Trefethen, ATAP, Thm 15.2: 2**(n-2)/n**2 < Lambda_n < 2**(n+3)/n.
    assert np.all(2.0 ** (ns - 2) / ns**2 < lam) and np.all(lam < 2.0 ** (ns + 3) / ns)
    # Asymptotics 2**(n+1) / (e n log n): within 20 % from n = 20 on.
    asym = 2.0 ** (ns + 1) / (math.e * ns * np.log(ns))
    assert np.all(np.abs(lam[ns >= 20] / asym[ns >= 20] - 1) < 0.2)
    slope = np.polyfit(ns, np.log2(lam), 1)[0]  # log2 Lambda grows ~ n
    assert 0.85 < slope < 1.05


def test_lebesgue_constant_grows_logarithmically_for_chebyshev_nodes():
    ns = np.array([2, 4, 8, 16, 32, 64, 128, 256, 512])
    lam2 = np.array([lebesgue_constant(chebyshev_nodes(n)) for n in ns])
    lam1 = np.array([lebesgue_constant(chebyshev_nodes(n, kind=1)) for n in ns])
    low = 2 / np.pi * np.log(ns + 1) + 0.52125  # any node set (ATAP, Thm 15.2)
    high = 2 / np.pi * np.log(ns + 1) + 1.0  # Chebyshev points
    assert np.all(low <= lam2) and np.all(lam2 <= high)
    assert np.all(lam1 <= high)
    # Each doubling of n adds (2/pi) log 2 ~ 0.441 asymptotically.
    assert np.allclose(np.diff(lam2)[-4:], 2 / np.pi * math.log(2), atol=2e-3)


def test_lebesgue_constant_validates():
    with pytest.raises(ValueError, match=r"nodes\[0\] == nodes\[1\]"):
        lebesgue_constant([1.0, 1.0])
    with pytest.raises(ValueError, match=r"`weights` must be non-zero"):
        lebesgue_constant([0.0, 1.0], [1.0, 0.0])


# --------------------------------------------------------------------------
# Documentation
# --------------------------------------------------------------------------
