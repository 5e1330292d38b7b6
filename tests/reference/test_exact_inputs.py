"""Every input the reference accepts gives the right answer, and what it cannot
honour is refused with a message naming the argument.

Classes: integer coordinates beyond ``2**53`` (int64 near ``2**62``, Python
ints, beyond int64, ints mixed with floats) in the exact predicates, hull and
Delaunay; complex, masked and overflowing input; integer nodes and knots that
doubles would merge; extrapolation far outside the nodes. Oracles are exact
integer and rational arithmetic.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from reference import (
    CubicSpline,
    barycentric_interpolate,
    barycentric_weights,
    bezier,
    chebyshev_nodes,
    chebyshev_weights,
    convex_hull,
    delaunay,
    equispaced_nodes,
    incircle,
    incircle_many,
    is_delaunay,
    lebesgue_constant,
    orient2d,
    orient2d_many,
    parametric_spline,
)

BIG = 2**62


def exact_orient(p, q, r) -> int:
    p, q, r = ([Fraction(v) for v in pt] for pt in (p, q, r))
    det = (p[0] - r[0]) * (q[1] - r[1]) - (p[1] - r[1]) * (q[0] - r[0])
    return (det > 0) - (det < 0)


def exact_incircle(a, b, c, d) -> int:
    a, b, c, d = ([Fraction(v) for v in pt] for pt in (a, b, c, d))
    rows = [(p[0] - d[0], p[1] - d[1]) for p in (a, b, c)]
    (ax, ay), (bx, by), (cx, cy) = rows
    det = ((ax * ax + ay * ay) * (bx * cy - cx * by) + (bx * bx + by * by) * (cx * ay - ax * cy)
           + (cx * cx + cy * cy) * (ax * by - bx * ay))  # fmt: skip
    s = (det > 0) - (det < 0)
    return s * exact_orient(a, b, c)


def exact_hull(points) -> list[int]:
    """Counter-clockwise hull from the lexicographically smallest point, exact."""
    pts = [tuple(int(v) for v in p) for p in points]
    order = sorted(range(len(pts)), key=lambda i: (pts[i], i))
    uniq = []
    for i in order:
        if not uniq or pts[uniq[-1]] != pts[i]:
            uniq.append(i)

    def left(a, b, c):  # integer orientation determinant > 0
        return (a[0] - c[0]) * (b[1] - c[1]) - (a[1] - c[1]) * (b[0] - c[0]) > 0

    def chain(seq):
        out = []
        for i in seq:
            while len(out) >= 2 and not left(pts[out[-2]], pts[out[-1]], pts[i]):
                out.pop()
            out.append(i)
        return out

    lower, upper = chain(uniq), chain(uniq[::-1])
    return lower[:-1] + upper[:-1]


# ---------------------------------------------------------------------------
# Integer coordinates beyond 2**53 are exact
# ---------------------------------------------------------------------------


def test_orient2d_int64_near_2_62_is_exact():
    p, q, r = np.array([[5, 8], [BIG - 3, BIG - 1], [BIG - 2, BIG]], dtype=np.int64)
    assert float(q[0]) == float(r[0]) and float(q[1]) == float(r[1])  # doubles merge q, r
    assert orient2d(p, q, r) == exact_orient(p.tolist(), q.tolist(), r.tolist()) == 1
    assert orient2d(p, r, q) == -1
    p, q, r = np.array([[0, 0], [BIG, BIG + 1], [BIG + 1, BIG + 2]], dtype=np.int64)
    assert orient2d(p, q, r) == exact_orient(p.tolist(), q.tolist(), r.tolist()) == -1


def test_orient2d_python_ints_beyond_2_53():
    p, q, r = [3, 1], [2**53 + 5, 2], [2**53 + 3, 2]  # 2**53 + 5 and + 3 are not doubles
    assert orient2d(p, q, r) == exact_orient(p, q, r) == 1
    assert orient2d(q, p, r) == -1


def test_orient2d_integers_beyond_int64_and_mixed_with_floats():
    p, q, r = [0, 0], [2**70 + 1, 2**70], [2**71 + 2, 2**71 + 1]
    assert orient2d(p, q, r) == exact_orient(p, q, r) == 1
    # a list mixing a big integer with a fraction is read exactly, not rounded
    p, q, r = [0.5, 0.25], [2**53 + 1, 0.75], [2**53 + 3, 1.25]
    assert orient2d(p, q, r) == exact_orient(p, q, r)
    obj = np.array([[0, 0], [2**80, 1], [2**81, 3]], dtype=object)
    assert orient2d(*obj) == exact_orient(*obj.tolist()) == 1


def test_orient2d_many_int64_matches_exact():
    rng = np.random.default_rng(7)
    base = rng.integers(-4, 5, size=(200, 3, 2))
    pts = (base + np.array([BIG, -BIG], dtype=np.int64)).astype(np.int64)
    got = orient2d_many(pts[:, 0], pts[:, 1], pts[:, 2])
    want = [exact_orient(*t) for t in pts.tolist()]
    assert got.tolist() == want
    assert got.dtype == np.int8


def test_incircle_int64_near_2_62_is_exact():
    s = 2**60
    a, b, c = [BIG, BIG], [BIG + 2 * s, BIG], [BIG, BIG + 2 * s]
    on = [BIG + 2 * s, BIG + 2 * s]  # the fourth corner of the square: cocircular
    inside = [BIG + 2 * s - 1, BIG + 2 * s - 1]
    outside = [BIG + 2 * s + 1, BIG + 2 * s]
    arr = lambda v: np.array(v, dtype=np.int64)  # noqa: E731
    assert incircle(arr(a), arr(b), arr(c), arr(on)) == 0
    assert incircle(arr(a), arr(b), arr(c), arr(inside)) == exact_incircle(a, b, c, inside) == 1
    assert incircle(arr(a), arr(c), arr(b), arr(outside)) == -1
    many = incircle_many(arr(a), arr(b), arr(c), arr([on, inside, outside]))
    assert many.tolist() == [0, 1, -1]


def test_convex_hull_of_int64_points_near_2_62():
    offsets = [(0, 0), (4, 0), (4, 4), (0, 4), (2, 2), (1, 0), (2, 1), (3, 3), (4, 1)]
    pts = np.array([(BIG + x, BIG + y) for x, y in offsets], dtype=np.int64)
    pts[7] += np.array([1, -1])  # (BIG + 4, BIG + 2): on the right edge
    pts = np.vstack([pts, [[BIG + 2, BIG - 1]]])  # below the bottom edge: a vertex
    want = exact_hull(pts.tolist())
    for method in ("monotone", "jarvis"):
        assert convex_hull(pts, method=method).tolist() == want
    assert convex_hull(pts - BIG).tolist() == want  # the same shape near 0


def test_convex_hull_python_ints_beyond_int64():
    rng = np.random.default_rng(3)
    small = rng.integers(-50, 50, size=(60, 2)).tolist()
    big = [[x * 2**70 + 1, y * 2**70 - 3] for x, y in small]
    want = exact_hull(big)
    for method in ("monotone", "jarvis"):
        assert convex_hull(big, method=method).tolist() == want


def test_convex_hull_prefilter_on_rounded_int64_keeps_every_vertex():
    # > 2048 points: both prefilter passes run on the rounded, translated
    # coordinates. The bottom edge bulges by at most 400 units (doubles near
    # 2**62 are 1024 apart), so each of its 41 points is a vertex only exactly.
    rng = np.random.default_rng(5)
    inner = rng.integers(-2**40, 2**40, size=(3000, 2))
    corners = np.array([[-2**41, -2**41], [2**41, -2**41], [2**41, 2**41], [-2**41, 2**41]])
    edge = np.c_[np.linspace(-2**41, 2**41, 41).astype(np.int64), np.full(41, -2**41)]
    k = np.arange(41)
    edge[:, 1] -= k * (40 - k)
    pts = np.vstack([inner, corners, edge]).astype(np.int64) + BIG
    want = exact_hull(pts.tolist())
    assert len(want) == 43
    for method in ("monotone", "jarvis"):
        assert convex_hull(pts, method=method).tolist() == want


def _triangle_set(tri) -> set[tuple[int, ...]]:
    return {tuple(sorted(t)) for t in np.asarray(tri).tolist()}


def test_delaunay_of_int64_points_near_2_62_matches_the_translated_set():
    rng = np.random.default_rng(11)
    small = rng.integers(0, 1000, size=(40, 2)) * 7 + rng.integers(0, 3, size=(40, 2))
    pts = small.astype(np.int64) + BIG
    tri = delaunay(pts)
    assert is_delaunay(pts, tri)
    assert not is_delaunay(pts.astype(float), tri) or True  # doubles may merge points
    assert _triangle_set(tri) == _triangle_set(delaunay(small))


def test_delaunay_int64_diagonal_decided_exactly():
    s = 2**40
    # a square with one corner pulled in by 1 (doubles would round it back onto
    # the circle): only the diagonal through that corner is Delaunay
    pts = np.array([[BIG, BIG], [BIG + s, BIG], [BIG + s - 1, BIG + s - 1], [BIG, BIG + s]],
                   dtype=np.int64)  # fmt: skip
    tri = delaunay(pts)
    assert is_delaunay(pts, tri)
    assert _triangle_set(tri) == {(0, 1, 2), (0, 2, 3)}


# ---------------------------------------------------------------------------
# Refused input: complex, masked, overflowing
# ---------------------------------------------------------------------------

COMPLEX_CALLS = {
    "orient2d p": (lambda: orient2d([0, 1j], [1, 0], [0, 1]), "`p`"),
    "convex_hull": (lambda: convex_hull(np.array([[0, 0], [1, 0], [0, 1]], complex)), "`points`"),
    "delaunay": (lambda: delaunay(np.array([[0, 0], [1, 0], [0, 1]], complex)), "`points`"),
    "nodes": (lambda: barycentric_interpolate([0, 1 + 0j], [1, 2], 0.5), "`nodes`"),
    "values": (lambda: barycentric_interpolate([0, 1], [1, 2j], 0.5), "`values`"),
    "t": (lambda: barycentric_interpolate([0, 1], [1, 2], 0.5 + 0j), "`t`"),
    "ctrl": (lambda: bezier(np.array([[0, 0], [1, 1j]]), 0.5), "`ctrl`"),
    "spline t": (lambda: CubicSpline([0, 1, 2], [0, 1, 0])(np.array([0.5 + 0j])), "`t`"),
    "spline x": (lambda: CubicSpline([0, 1, 2 + 0j], [0, 1, 0]), "`x`"),
}


@pytest.mark.parametrize("case", sorted(COMPLEX_CALLS))
def test_complex_input_is_refused_not_truncated(case):
    call, name = COMPLEX_CALLS[case]
    with pytest.raises(ValueError, match=rf"{name} must contain real values"):
        call()


MASKED_CALLS = {
    "convex_hull": (lambda m: convex_hull(np.ma.array([[0, 0], [1, 0], [0, 1], [9, 9]],
                                                     mask=m)), "`points`"),  # fmt: skip
    "orient2d_many": (lambda m: orient2d_many([0, 0], [1, 0], np.ma.array([[0, 1], [9, 9]],
                                                                         mask=m[2:])), "`r`"),  # fmt: skip
    "nodes": (lambda m: barycentric_weights(np.ma.array([0.0, 1.0, 2.0, 9.0], mask=m[:, 0])),
              "`nodes`"),  # fmt: skip
}


@pytest.mark.parametrize("case", sorted(MASKED_CALLS))
def test_masked_arrays_are_refused(case):
    call, name = MASKED_CALLS[case]
    mask = np.array([[False, False], [False, False], [False, False], [True, True]])
    with pytest.raises(ValueError, match=rf"{name} must be a plain array, not a masked array"):
        call(mask)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: orient2d([0, 0], [10**400, 1], [1, 1]), "`q`"),
        (lambda: convex_hull([[0, 0], [1, 10**309], [1, 1]]), "`points`"),
        (lambda: barycentric_interpolate([0, 1], [1, 2], 10**400), "`t`"),
        (lambda: barycentric_weights([0, 10**400]), "`nodes`"),
        (lambda: CubicSpline([0, 1, 2], [0, 10**400, 0]), "`y`"),
        (lambda: parametric_spline([[0, 0], [1, -(10**400)]]), "`points`"),
    ],
)
def test_numbers_too_large_for_a_double_are_refused_clearly(call, name):
    with pytest.raises(ValueError, match=rf"{name} must hold values that fit in a double"):
        call()


def test_nan_is_still_refused_with_its_own_message():
    with pytest.raises(ValueError, match="`t` must contain only finite values"):
        barycentric_interpolate([0, 1], [1, 2], [0.5, np.nan])


# ---------------------------------------------------------------------------
# Integer nodes and knots that doubles would merge
# ---------------------------------------------------------------------------


def test_distinct_int64_nodes_are_not_called_equal():
    nodes = np.array([BIG + 2, BIG, BIG + 1], dtype=np.int64)  # equal as doubles
    w = barycentric_weights(nodes)
    assert np.allclose(w, barycentric_weights([2.0, 0.0, 1.0]))
    assert lebesgue_constant(nodes) == pytest.approx(1.25)
    t = np.array([BIG + 3, BIG + 1, BIG - 1], dtype=np.int64)
    got = barycentric_interpolate(nodes, [4.0, 0.0, 1.0], t)  # s**2 with s = t - BIG
    assert got.tolist() == pytest.approx([9.0, 1.0, 1.0], rel=1e-14)


def test_nodes_too_far_apart_for_doubles_are_refused_without_calling_them_equal():
    nodes = np.array([-BIG, -BIG + 1, BIG, BIG + 1], dtype=np.int64)
    with pytest.raises(ValueError, match="distinct integers") as info:
        barycentric_weights(nodes)
    assert "==" not in str(info.value)


def test_increasing_int64_knots_are_accepted():
    x = np.array([BIG, BIG + 1, BIG + 3, BIG + 4], dtype=np.int64)
    s = x - BIG
    spline = CubicSpline(x, (s**3).astype(float), bc_type="not-a-knot")  # reproduces cubics
    t = np.array([BIG + 2, BIG + 4], dtype=np.int64)
    assert spline(t).tolist() == pytest.approx([8.0, 64.0], rel=1e-13)
    assert spline(np.array([BIG + 2]), nu=1).tolist() == pytest.approx([12.0], rel=1e-13)
    small = CubicSpline(np.arange(6, dtype=np.int64), np.arange(6.0) ** 2)
    assert small(2.5) == pytest.approx(CubicSpline(np.arange(6.0), np.arange(6.0) ** 2)(2.5))


# ---------------------------------------------------------------------------
# Extrapolation
# ---------------------------------------------------------------------------


def exact_interpolant(x, y, t) -> Fraction:
    xs, ys, t = [Fraction(v) for v in x], [Fraction(v) for v in y], Fraction(t)
    total = Fraction(0)
    for j, xj in enumerate(xs):
        basis = Fraction(1)
        for k, xk in enumerate(xs):
            if k != j:
                basis *= (t - xk) / (xj - xk)
        total += basis * ys[j]
    return total


def _relative_error(got: float, exact: Fraction) -> float:
    return float(abs(Fraction(float(got)) - exact) / abs(exact))


@pytest.mark.parametrize("t", [1e2, 1e3, 1e4, -1e2, -1e3, -1e4])
def test_quartic_on_five_equispaced_nodes_extrapolates_accurately(t):
    x = np.linspace(2.0, 4.0, 5)
    y = 0.5 * x**4 - 3 * x**3 + x**2 + 7 * x - 11
    got = barycentric_interpolate(x, y, t)
    assert _relative_error(got, exact_interpolant(x, y, t)) < 1e-12


def test_far_extrapolation_stays_finite():
    assert barycentric_interpolate([0, 1], [3, 3], 1e300) == 3.0
    assert barycentric_interpolate([2.0, 5.0, 7.0, 9.0], [-4.0] * 4, -1e300) == -4.0
    got = barycentric_interpolate([-1, 0, 1], [1, 0, 1], 1e17)
    assert got == pytest.approx(1e34, rel=1e-15)
    line = barycentric_interpolate([1.0, 2.0, 3.0], [2.0, 4.0, 6.0], 1e300)  # y = 2x
    assert line == pytest.approx(2e300, rel=1e-15)
    assert np.isinf(barycentric_interpolate([-1, 0, 1], [1, 0, 1], 1e200))  # 1e400 itself


@pytest.mark.parametrize("n, t", [(12, 1.5), (12, -3.0), (12, 40.0), (30, 1.01), (30, -1.3)])
def test_extrapolation_error_within_the_documented_bound(n, t):
    rng = np.random.default_rng(n)
    x = chebyshev_nodes(n)
    y = rng.standard_normal(n + 1)
    exact = exact_interpolant(x, y, t)
    got = barycentric_interpolate(x, y, t)
    # B(t) = (5n + 5) u sum_j |l_j(t) f_j| (Higham 2004); the result is within 2 B(t)
    xs = [Fraction(v) for v in x]
    size = Fraction(0)
    for j in range(n + 1):
        basis = Fraction(1)
        for k in range(n + 1):
            if k != j:
                basis *= (Fraction(t) - xs[k]) / (xs[j] - xs[k])
        size += abs(basis * Fraction(y[j]))
    bound = 2 * (5 * n + 5) * Fraction(2.0**-53) * size
    assert abs(Fraction(float(got)) - exact) <= bound * Fraction(11, 10)


def test_polynomial_weights_given_explicitly_extrapolate_the_same_way():
    x = chebyshev_nodes(8)
    y = np.cos(x)
    t = np.array([1.5, -2.0, 30.0])
    assert np.allclose(barycentric_interpolate(x, y, t, chebyshev_weights(8)),
                       barycentric_interpolate(x, y, t), rtol=1e-13)  # fmt: skip


def test_rational_weights_keep_the_second_formula_outside():
    x = np.linspace(-1.0, 1.0, 7)
    w = (-1.0) ** np.arange(7)  # Berrut's rational interpolant, not a polynomial
    y = np.exp(x)
    t = 2.5
    q = w / (t - x)
    expected = (q @ y) / q.sum()
    assert barycentric_interpolate(x, y, t, w) == pytest.approx(expected, rel=1e-14)


def test_node_hits_and_inside_points_unchanged():
    x = equispaced_nodes(6)
    y = np.sin(3 * x) + 0.1
    assert np.array_equal(barycentric_interpolate(x, y, x), y)
    t = np.linspace(-1, 1, 11)
    w = barycentric_weights(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = w / (t[:, None] - x)
        second = (q @ y) / q.sum(axis=1)
    inside = ~np.isin(t, x)
    np.testing.assert_allclose(barycentric_interpolate(x, y, t)[inside], second[inside], rtol=1e-15)
