"""Tests of reference.CubicSpline and reference.parametric_spline against SciPy and against the mathematics."""

from __future__ import annotations

import re

import numpy as np
import pytest
import scipy.interpolate as si
from hypothesis import given, settings
from hypothesis import strategies as st

import reference._splines as splines
from reference import CubicSpline, ParametricSpline, parametric_spline

# Coefficients agree with SciPy's to rounding: both solve the same slope system
# with a banded LU; differences come from row scaling and the order of operations.
C_RTOL = 1e-12
# Values and derivatives are polynomials in (t - x_i) of those coefficients.
V_RTOL = 1e-11

BC_TYPES = {
    "natural": "natural",
    "clamped": "clamped",
    "not-a-knot": "not-a-knot",
    "periodic": "periodic",
    "first-second": ((1, 0.5), (2, -1.0)),
    "second-first": ((2, 0.3), (1, -2.0)),
    "nak-natural": ("not-a-knot", "natural"),
    "clamped-nak": ("clamped", "not-a-knot"),
}


def random_data(rng: np.random.Generator, n: int, d: int | None, periodic: bool):
    """Knots with spacing in [0.1, 1] (well-conditioned) and normal values."""
    x = np.cumsum(rng.uniform(0.1, 1.0, n)) - 0.5
    y = rng.normal(size=(n,) if d is None else (n, d))
    if periodic:
        y[-1] = y[0]
    return x, y


def widen(bc, d: int | None):
    """Give derivative values the shape of one y value."""
    if isinstance(bc, str) or d is None:
        return bc
    return tuple(b if isinstance(b, str) else (b[0], np.full(d, b[1])) for b in bc)


def assert_same_as_scipy(x, y, bc):
    ours = CubicSpline(x, y, bc_type=bc)
    ref = si.CubicSpline(x, y, bc_type=bc)
    scale = np.abs(ref.c).max()
    np.testing.assert_allclose(ours.c, ref.c, rtol=C_RTOL, atol=C_RTOL * scale)
    np.testing.assert_array_equal(ours.x, ref.x)
    span = x[-1] - x[0]
    t = np.concatenate([x, np.linspace(x[0] - 0.3 * span, x[-1] + 0.3 * span, 101)])
    for nu in range(4):
        want = ref(t, nu)
        got = ours(t, nu)
        assert got.shape == want.shape
        atol = V_RTOL * max(np.abs(want).max(), scale)
        np.testing.assert_allclose(got, want, rtol=V_RTOL, atol=atol)


@pytest.mark.parametrize("name", list(BC_TYPES))
@pytest.mark.parametrize("n", [2, 3, 4, 5, 8, 31])
@pytest.mark.parametrize("d", [None, 3])
def test_matches_scipy(name, n, d):
    rng = np.random.default_rng([n, 0 if d is None else d, len(name)])
    bc = widen(BC_TYPES[name], d)
    x, y = random_data(rng, n, d, periodic=bc == "periodic")
    assert_same_as_scipy(x, y, bc)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(2, 40),
    name=st.sampled_from(list(BC_TYPES)),
)
def test_matches_scipy_random(seed, n, name):
    rng = np.random.default_rng(seed)
    bc = BC_TYPES[name]
    x, y = random_data(rng, n, None, periodic=bc == "periodic")
    x = x * rng.uniform(0.01, 100.0)  # any scale
    assert_same_as_scipy(x, y, bc)


@pytest.mark.parametrize("n", [4, 7, 50])
def test_not_a_knot_matches_fitpack(n):
    """FITPACK's interpolating cubic (s=0) uses not-a-knot end conditions."""
    rng = np.random.default_rng(n)
    x, y = random_data(rng, n, None, periodic=False)
    tck = si.splrep(x, y, k=3, s=0)
    ours = CubicSpline(x, y, bc_type="not-a-knot")
    t = np.linspace(x[0], x[-1], 301)
    for nu in range(4):
        want = si.splev(t, tck, der=nu)
        np.testing.assert_allclose(ours(t, nu), want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


@pytest.mark.parametrize("order", ["sorted", "shuffled"])
def test_pieces_at_the_knots_match_scipy(order):
    """At a knot the third derivative jumps; both take the piece to the right.

    Many sorted points take a different search path than unsorted ones.
    """
    rng = np.random.default_rng(11)
    x, y = random_data(rng, 12, None, periodic=False)
    t = np.sort(np.concatenate([np.repeat(x, 5), np.linspace(x[0] - 1, x[-1] + 1, 200)]))
    if order == "shuffled":
        t = rng.permutation(t)
    ours, ref = CubicSpline(x, y, "not-a-knot"), si.CubicSpline(x, y, bc_type="not-a-knot")
    for nu in range(4):
        np.testing.assert_allclose(ours(t, nu), ref(t, nu), rtol=1e-11, atol=1e-11)


def test_default_bc_is_natural():
    x, y = random_data(np.random.default_rng(1), 9, None, periodic=False)
    np.testing.assert_array_equal(CubicSpline(x, y).c, CubicSpline(x, y, "natural").c)
    assert CubicSpline(x, y).bc_type == "natural"


def test_attributes_and_shapes():
    x, y = random_data(np.random.default_rng(2), 6, 2, periodic=False)
    s = CubicSpline(x, y)
    assert s.c.shape == (4, 5, 2)
    assert s.x.shape == (6,)
    assert s(0.5).shape == (2,)
    assert s([0.5, 1.0, 2.0]).shape == (3, 2)
    assert s(np.zeros((2, 3))).shape == (2, 3, 2)
    scalar = CubicSpline(x, y[:, 0])(0.5)
    assert np.ndim(scalar) == 0 and isinstance(float(scalar), float)


def test_input_is_copied():
    x, y = random_data(np.random.default_rng(3), 6, None, periodic=False)
    s = CubicSpline(x, y)
    before = s(1.3)
    x[:] = 0.0
    y[:] = 0.0
    assert s(1.3) == before


@pytest.mark.parametrize("h_factor", [1.0, 1e-3, 1e3])
def test_natural_second_derivative_vanishes_at_ends(h_factor):
    x, y = random_data(np.random.default_rng(4), 12, None, periodic=False)
    s = CubicSpline(x * h_factor, y, bc_type="natural")
    scale = np.abs(s(s.x, 2)).max()
    assert abs(s(s.x[0], 2)) <= 1e-12 * scale
    assert abs(s(s.x[-1], 2)) <= 1e-12 * scale


def test_clamped_and_given_derivatives_at_ends():
    x, y = random_data(np.random.default_rng(5), 10, None, periodic=False)
    s = CubicSpline(x, y, bc_type="clamped")
    assert abs(s(x[0], 1)) < 1e-13 and abs(s(x[-1], 1)) < 1e-13
    s = CubicSpline(x, y, bc_type=((1, 2.5), (2, -4.0)))
    assert s(x[0], 1) == pytest.approx(2.5, abs=1e-12)
    assert s(x[-1], 2) == pytest.approx(-4.0, abs=1e-10)


def test_spline_is_c2_at_interior_knots():
    x, y = random_data(np.random.default_rng(6), 15, None, periodic=False)
    for bc in ("natural", "not-a-knot", ((1, 1.0), (1, 1.0))):
        s = CubicSpline(x, y, bc_type=bc)
        h = np.diff(x)[:, None] ** np.arange(3, -1, -1)  # (t - x_i)^k at the right end
        right = [np.sum(s.c[:, :-1].T * h[:-1], axis=1)]
        right.append(np.sum(s.c[:3, :-1].T * np.arange(3, 0, -1) * h[:-1, 1:], axis=1))
        right.append(np.sum(s.c[:2, :-1].T * np.array([6, 2]) * h[:-1, 2:], axis=1))
        left = [s.c[3, 1:], s.c[2, 1:], 2 * s.c[1, 1:]]
        for a, b in zip(right, left):
            np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11 * np.abs(b).max())


def test_not_a_knot_third_derivative_continuous_at_second_knots():
    x, y = random_data(np.random.default_rng(7), 9, None, periodic=False)
    s = CubicSpline(x, y, bc_type="not-a-knot")
    assert s.c[0, 0] == pytest.approx(s.c[0, 1], rel=1e-10)
    assert s.c[0, -1] == pytest.approx(s.c[0, -2], rel=1e-10)


def test_periodic_wraps_and_matches_derivatives():
    x, y = random_data(np.random.default_rng(8), 11, 2, periodic=True)
    s = CubicSpline(x, y, bc_type="periodic")
    period = x[-1] - x[0]
    t = np.linspace(x[0], x[-1], 37)
    for nu in range(3):
        np.testing.assert_allclose(s(x[0], nu), s(x[-1], nu), atol=1e-10)
        np.testing.assert_allclose(s(t + 2 * period, nu), s(t, nu), atol=1e-9)
        np.testing.assert_allclose(s(t - period, nu), s(t, nu), atol=1e-9)


def test_extrapolation_continues_end_polynomials():
    x, y = random_data(np.random.default_rng(9), 7, None, periodic=False)
    s = CubicSpline(x, y, bc_type="not-a-knot")
    assert s(x[0] - 2.0) == pytest.approx(np.polyval(s.c[:, 0], -2.0))
    u = x[-1] + 1.5 - x[-2]
    assert s(x[-1] + 1.5) == pytest.approx(np.polyval(s.c[:, -1], u))


@pytest.mark.parametrize("bc", ["not-a-knot", ((1, 0.0), (1, 3 * 4.0**2))])
def test_reproduces_cubics(bc):
    x = np.array([0.0, 0.5, 1.7, 2.0, 3.1, 4.0])
    p = np.array([1.0, -2.0, 0.5, 3.0])  # x^3 - 2x^2 + x/2 + 3
    if not isinstance(bc, str):
        dp = np.polyder(p)
        bc = ((1, np.polyval(dp, 0.0)), (1, np.polyval(dp, 4.0)))
    s = CubicSpline(x, np.polyval(p, x), bc_type=bc)
    t = np.linspace(-1, 5, 50)
    for nu in range(4):
        np.testing.assert_allclose(s(t, nu), np.polyval(np.polyder(p, nu), t), atol=1e-10)


def test_two_and_three_point_special_cases():
    line = CubicSpline([1.0, 3.0], [2.0, 6.0], bc_type="not-a-knot")
    np.testing.assert_allclose(line.c[:, 0], [0.0, 0.0, 2.0, 2.0], atol=1e-15)
    x = np.array([0.0, 1.0, 3.0])
    parabola = CubicSpline(x, x**2 - x, bc_type="not-a-knot")
    t = np.linspace(-1, 4, 11)
    np.testing.assert_allclose(parabola(t), t**2 - t, atol=1e-13)
    constant = CubicSpline([0.0, 2.0], [5.0, 5.0], bc_type="periodic")
    assert constant(7.3) == 5.0


def convergence_errors(f, bc, ns):
    t = np.linspace(0.0, np.pi, 2001)
    errors = []
    for n in ns:
        x = np.linspace(0.0, np.pi, n + 1)
        errors.append(np.abs(CubicSpline(x, f(x), bc_type=bc)(t) - f(t)).max())
    return np.array(errors)


@pytest.mark.parametrize(
    "f, bc",
    [
        (np.cos, "clamped"),  # cos' = 0 at 0 and pi, so "clamped" is the complete spline
        (lambda x: np.exp(np.sin(x)), "not-a-knot"),
        (lambda x: np.exp(np.sin(x)), ((1, 1.0), (1, -1.0))),
    ],
    ids=["clamped-cos", "not-a-knot", "complete"],
)
def test_fourth_order_convergence(f, bc):
    errors = convergence_errors(f, bc, [16, 32, 64, 128])
    ratios = errors[:-1] / errors[1:]
    assert np.all((ratios > 12) & (ratios < 20)), ratios


def test_natural_spline_is_only_second_order_at_the_ends():
    """A reminder of why the natural end condition loses accuracy (f'' != 0 at the ends)."""
    errors = convergence_errors(lambda x: np.exp(np.sin(x)), "natural", [16, 32, 64, 128])
    ratios = errors[:-1] / errors[1:]
    assert np.all(ratios < 8), ratios


def test_large_n():
    """n = 200001 knots: a dense solve would need 320 GB; the banded one is instant."""
    x = np.linspace(0.0, 1.0, 200_001)
    s = CubicSpline(x, np.sin(7 * x), bc_type="not-a-knot")
    assert s.c.shape == (4, 200_000)
    p = CubicSpline(x, np.sin(2 * np.pi * x).round(12), bc_type="periodic")
    assert abs(p(0.25) - 1.0) < 1e-12


# --- errors ---------------------------------------------------------------


@pytest.mark.parametrize(
    "x, y, bc, message",
    [
        ([0.0, 1.0, 2.0, 1.0, 3.0], [1, 2, 3, 4, 5], "natural",
         "`x` must be strictly increasing; x[3] = 1.0 is not greater than x[2] = 2.0."),
        ([0.0, 1.0, 2.0, 2.0], [1, 2, 3, 4], "natural",
         "`x` must be strictly increasing; x[3] = 2.0 is not greater than x[2] = 2.0."),
        ([0.0], [1.0], "natural", "`x` must contain at least 2 points; got 1."),
        ([0.0, 1.0, 2.0], [1.0, 2.0], "natural", "`y` must hold one value per entry of `x`"),
        ([[0.0, 1.0]], [1.0, 2.0], "natural", "`x` must be 1-dimensional"),
        ([0.0, 1.0, 2.0], np.ones((3, 2, 2)), "natural", "`y` must have shape (n,) or (n, d)"),
        ([0.0, np.nan, 2.0], [1, 2, 3], "natural", "`x` must contain only finite values"),
        ([0.0, 1.0, 2.0], [1, np.inf, 3], "natural", "`y` must contain only finite values"),
        ([0.0, 1.0, 2.0], [1j, 2, 3], "natural", "`y` must contain real values"),
        ([0.0, 1.0, 2.0], [1.0, 2.0, 1.5], "periodic",
         "`y[0]` and `y[-1]` must be equal when bc_type='periodic'"),
        ([0.0, 1.0, 2.0], [1, 2, 3], "natral", "`bc_type` must be one of 'natural'"),
        ([0.0, 1.0, 2.0], [1, 2, 3], ("natural",), "`bc_type` must be a string or a pair"),
        ([0.0, 1.0, 2.0], [1, 2, 3], 3, "`bc_type` must be a string or a pair"),
        ([0.0, 1.0, 2.0], [1, 2, 3], ("periodic", "natural"), "'periodic' applies to both ends"),
        ([0.0, 1.0, 2.0], [1, 2, 3], ("natural", "flat"), "`bc_type[1]` must be one of"),
        ([0.0, 1.0, 2.0], [1, 2, 3], ((3, 0.0), "natural"),
         "`bc_type[0]` derivative order must be 1 or 2; got 3."),
        ([0.0, 1.0, 2.0], [1, 2, 3], ((1, 0.0, 2), "natural"), "`bc_type[0]` must be"),
        ([0.0, 1.0, 2.0], [1, 2, 3], ((1, [0.0, 1.0]), "natural"),
         "`bc_type[0][1]` (the derivative value) must have shape ()"),
        ([0.0, 1.0, 2.0], np.ones((3, 2)), ((1, 0.0), "natural"),
         "`bc_type[0][1]` (the derivative value) must have shape (2,)"),
    ],
)
def test_bad_input_is_rejected(x, y, bc, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        CubicSpline(x, y, bc_type=bc)


def test_periodic_accepts_two_and_three_points_like_scipy():
    for n in (2, 3):
        x = np.arange(float(n))
        y = np.zeros(n)
        assert_same_as_scipy(x, y, "periodic")
    with pytest.raises(ValueError, match="must be equal when bc_type='periodic'"):
        CubicSpline([0.0, 1.0], [0.0, 1.0], "periodic")


@pytest.mark.parametrize(
    "t, nu, message",
    [
        (np.nan, 0, "`t` must contain only finite values"),
        (0.5, -1, "`nu` must be >= 0; got -1."),
        (0.5, 1.0, "`nu` must be an integer; got 1.0."),
        ("a", 0, "`t` must be an array of real numbers"),
    ],
)
def test_bad_evaluation_input(t, nu, message):
    s = CubicSpline([0.0, 1.0, 2.0], [0.0, 1.0, 0.0])
    with pytest.raises(ValueError, match=re.escape(message)):
        s(t, nu)


def test_derivatives_above_three_are_zero():
    s = CubicSpline([0.0, 1.0, 2.0], [[0.0, 1.0], [1.0, 0.0], [0.0, 2.0]])
    np.testing.assert_array_equal(s([0.2, 1.4], nu=4), np.zeros((2, 2)))


# --- parametric splines -----------------------------------------------------

STROKE = np.array([[0.0, 0.0], [1.0, 0.2], [1.5, 1.0], [1.2, 2.0], [3.0, 2.5], [4.0, 0.5]])


@pytest.mark.parametrize("parametrization", ["chord", "uniform", "centripetal"])
@pytest.mark.parametrize("bc", ["natural", "not-a-knot", "clamped"])
def test_parametric_interpolates_points_at_knots(parametrization, bc):
    curve = parametric_spline(STROKE, bc_type=bc, parametrization=parametrization)
    assert isinstance(curve, ParametricSpline)
    assert isinstance(curve.spline, CubicSpline)
    np.testing.assert_allclose(curve(curve.knots), STROKE, atol=1e-13)
    np.testing.assert_allclose(curve(curve.knots[2]), STROKE[2], atol=1e-13)
    assert curve(0.3).shape == (2,)


def test_parametric_knots():
    steps = np.linalg.norm(np.diff(STROKE, axis=0), axis=1)
    expected = {
        "uniform": np.arange(6.0),
        "chord": np.concatenate([[0.0], np.cumsum(steps)]),
        "centripetal": np.concatenate([[0.0], np.cumsum(np.sqrt(steps))]),
    }
    for name, knots in expected.items():
        curve = parametric_spline(STROKE, parametrization=name)
        np.testing.assert_allclose(curve.knots, knots, rtol=1e-15)
        assert curve.parametrization == name


def test_parametric_default_is_natural_chord():
    curve = parametric_spline(STROKE)
    ref = si.CubicSpline(curve.knots, STROKE, bc_type="natural")
    np.testing.assert_allclose(curve.spline.c, ref.c, rtol=1e-12, atol=1e-12)
    assert curve.parametrization == "chord"
    assert curve.spline.bc_type == "natural"


def test_parametric_sample_covers_whole_curve():
    curve = parametric_spline(STROKE)
    pts = curve.sample(num=57)
    assert pts.shape == (57, 2)
    np.testing.assert_allclose(pts[[0, -1]], STROKE[[0, -1]], atol=1e-13)
    assert curve.sample().shape == (200, 2)


def test_closed_stroke_with_periodic_bc():
    theta = np.linspace(0.0, 2 * np.pi, 13)
    circle = np.column_stack([np.cos(theta), np.sin(theta)])
    circle[-1] = circle[0]
    curve = parametric_spline(circle, bc_type="periodic")
    length = curve.knots[-1]
    for nu in range(3):
        np.testing.assert_allclose(curve(0.0, nu), curve(length, nu), atol=1e-12)
    radius = np.linalg.norm(curve.sample(400), axis=1)
    assert np.abs(radius - 1.0).max() < 1e-3


def test_parametric_in_three_dimensions():
    helix = np.column_stack([np.cos(np.arange(8.0)), np.sin(np.arange(8.0)), np.arange(8.0) / 4])
    curve = parametric_spline(helix, parametrization="centripetal")
    assert curve(curve.knots).shape == (8, 3)
    np.testing.assert_allclose(curve(curve.knots), helix, atol=1e-13)


@pytest.mark.parametrize(
    "points, kwargs, message",
    [
        ([[0, 0], [1, 1], [2, 0], [3, 1], [3, 1], [4, 0]], {},
         "`points[4]` repeats `points[3]`; remove repeated consecutive points."),
        ([[0, 0], [0, 0], [1, 1]], {"parametrization": "uniform"}, "`points[1]` repeats `points[0]`"),
        ([[0, 0]], {}, "`points` must hold at least 2 point(s); got 1."),
        ([0, 1, 2], {}, "`points` must have shape (n, d)"),
        ([[0, 0], [1, 1], [2, 0]], {"parametrization": "arc"}, "`parametrization` must be one of"),
        ([[0, 0], [1, 1], [2, 0]], {"bc_type": "periodic"}, "`points[-1]` must equal `points[0]`"),
        ([[0, 0], [1, 1], [2, 0]], {"bc_type": "free"}, "`bc_type` must be one of"),
    ],
)
def test_parametric_bad_input(points, kwargs, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parametric_spline(points, **kwargs)


def test_sample_rejects_bad_num():
    with pytest.raises(ValueError, match=re.escape("`num` must be >= 2; got 1.")):
        parametric_spline(STROKE).sample(num=1)
