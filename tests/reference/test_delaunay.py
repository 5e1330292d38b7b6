"""Tests of :mod:`reference.delaunay`: exact in-circle test and triangulations.

Oracles: exact determinants with :class:`fractions.Fraction`,
``scipy.spatial.Delaunay`` on points in general position (where the
triangulation is unique), and a brute-force empty-circumcircle check over
all points where it is not (cocircular grids, degenerate sets).
"""

from __future__ import annotations

import itertools
import time
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import Delaunay

from reference import convex_hull, delaunay, incircle, incircle_many, is_delaunay, orient2d_many

# ---------------------------------------------------------------------------
# Named datasets
# ---------------------------------------------------------------------------


def _integer_circle(r: int) -> list[tuple[int, int]]:
    """Every integer point on the circle of radius ``r`` (exactly cocircular)."""
    return [(x, y) for x in range(-r, r + 1) for y in range(-r, r + 1) if x * x + y * y == r * r]


def _datasets() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20240602)
    g = np.arange(8.0)
    grid = np.array([(x, y) for x in g for y in g])
    u = 2.0**-53
    kettner = np.array([(0.5 + k * u, 0.5 + l_ * u) for k in range(12) for l_ in range(12)])
    data = {
        "grid-8x8": grid,
        "grid-8x8-shuffled-dups": rng.permutation(np.vstack([grid, grid[::3]])),
        "circle-r65": np.array(_integer_circle(65), dtype=float),
        "circle-r65+centre": np.array(_integer_circle(65) + [(0, 0)], dtype=float),
        "kettner-grid+line": np.vstack([kettner, [[12, 12], [24, 24], [0, 1]]]),
        "collinear+apex": np.array([(i, i) for i in range(15)] + [(3, 5)], dtype=float),
        "line+two": np.array([(i, 0) for i in range(15)] + [(3, 5), (7, -2)], dtype=float),
        "sliver": np.array([(0, 0), (1, 1e-12), (2, 0), (1, -1e-12), (0.5, 0), (1.5, 0)]),
        "integers-0..5": rng.integers(0, 6, size=(80, 2)).astype(float),
        "huge": rng.random((60, 2)) * 1e300,
        "tiny": rng.random((60, 2)) * 1e-300,
        "mixed-scales": np.vstack([rng.random((30, 2)) * 1e-200, rng.random((30, 2))]),
        "random-300": rng.random((300, 2)),
    }
    return data


DATASETS = _datasets()


# ---------------------------------------------------------------------------
# Oracles
# ---------------------------------------------------------------------------


def exact_incircle(a, b, c, d) -> int:
    """(+1 inside, 0 on, -1 outside) with Fractions, any orientation of a, b, c."""
    ax, ay, bx, by, cx, cy, dx, dy = (Fraction(float(v)) for v in (*a, *b, *c, *d))
    orient = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    rows = [(px - dx, py - dy) for px, py in ((ax, ay), (bx, by), (cx, cy))]
    (a1, a2), (b1, b2), (c1, c2) = rows
    det = (
        (a1 * a1 + a2 * a2) * (b1 * c2 - c1 * b2)
        + (b1 * b1 + b2 * b2) * (c1 * a2 - a1 * c2)
        + (c1 * c1 + c2 * c2) * (a1 * b2 - b1 * a2)
    )
    s = (det > 0) - (det < 0)
    return s if orient > 0 else -s


def assert_empty_circumcircles(points: np.ndarray, tri: np.ndarray) -> None:
    """Global Delaunay property: no point strictly inside any circumcircle."""
    n = points.shape[0]
    for t in tri:
        a, b, c = (np.broadcast_to(points[i], (n, 2)) for i in t)
        assert np.all(incircle_many(a, b, c, points) <= 0), f"a point is inside the circle of {t}"


def distinct_count_and_boundary(points: np.ndarray) -> tuple[int, int]:
    """Distinct points and distinct points on the hull boundary (exact)."""
    uniq = np.unique(points, axis=0)
    hull = uniq[convex_hull(uniq)]
    on = np.zeros(len(uniq), dtype=bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0)):
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        on |= (orient2d_many(a, b, uniq) == 0) & np.all((uniq >= lo) & (uniq <= hi), axis=1)
    return len(uniq), int(on.sum())


def triangle_set(tri: np.ndarray) -> set[tuple[int, ...]]:
    return {tuple(t) for t in np.sort(tri, axis=1).tolist()}


def assert_valid_delaunay(points: np.ndarray, tri: np.ndarray) -> None:
    assert tri.dtype == np.intp and tri.ndim == 2 and tri.shape[1] == 3
    assert np.all(orient2d_many(points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]) > 0)
    n, h = distinct_count_and_boundary(points)
    assert tri.shape[0] == 2 * n - 2 - h  # Euler's formula for a triangulation
    assert is_delaunay(points, tri)
    assert_empty_circumcircles(points, tri)


# ---------------------------------------------------------------------------
# incircle
# ---------------------------------------------------------------------------


def test_incircle_basic_signs():
    a, b, c = [1, 0], [0, 1], [-1, 0]
    assert incircle(a, b, c, [0, 0]) == 1
    assert incircle(a, b, c, [0, -1]) == 0
    assert incircle(a, b, c, [3, 3]) == -1
    assert type(incircle(a, b, c, [0, 0])) is int


def test_incircle_independent_of_orientation():
    a, b, c = (1, 0), (0, 1), (-1, 0)
    for d, expected in (((0, 0), 1), ((0, -1), 0), ((2, 0), -1)):
        for perm in itertools.permutations((a, b, c)):
            assert incircle(*perm, d) == expected


def test_incircle_one_ulp_from_the_circle():
    a, b, c = (1.0, 0.0), (0.0, 1.0), (-1.0, 0.0)
    assert incircle(a, b, c, (0.0, np.nextafter(-1.0, 0.0))) == 1
    assert incircle(a, b, c, (0.0, np.nextafter(-1.0, -2.0))) == -1
    # points on an integer circle of radius 65, shifted by one ulp
    pts = np.array(_integer_circle(65), dtype=float)
    for d in pts[3:20]:
        assert incircle(pts[0], pts[1], pts[2], d) == 0
        assert incircle(pts[0], pts[1], pts[2], d * (1 + 2.0**-52)) == -1
        assert incircle(pts[0], pts[1], pts[2], d * (1 - 2.0**-53)) == 1


@pytest.mark.parametrize(
    "args, message",
    [
        (([0, 0], [1, 1], [2, 2], [0, 1]), "`a`, `b` and `c` must not be collinear"),
        (([0, 0], [0, 0], [1, 0], [0, 1]), "`a`, `b` and `c` must not be collinear"),
        (([0, 0], [1, 0], [0, 1], [np.nan, 0]), "`d` must contain only finite values"),
        (([0, 0], [1, 0, 2], [0, 1], [0, 0]), r"`b` must be a point of shape \(2,\)"),
    ],
)
def test_incircle_rejects_bad_input(args, message):
    with pytest.raises(ValueError, match=message):
        incircle(*args)


finite = st.floats(allow_nan=False, allow_infinity=False)
point = st.tuples(finite, finite)


@st.composite
def near_cocircular(draw):
    """Integer points of a circle, scaled, with a few ulps of noise on ``d``."""
    r = draw(st.sampled_from([5, 25, 65]))
    pts = draw(st.permutations(_integer_circle(r)))
    scale = draw(st.sampled_from([1.0, 0.1, 3.0e10, 2.0**-40]))
    a, b, c, d = (np.array(p, dtype=float) * scale for p in pts[:4])
    k = draw(st.integers(-3, 3))
    d = d + k * np.spacing(np.abs(d) + 1e-300)
    return tuple(map(tuple, (a, b, c, d)))


quads = st.one_of(st.tuples(point, point, point, point), near_cocircular())


@settings(max_examples=300, deadline=None)
@given(quads)
def test_incircle_matches_fraction_determinant(q):
    a, b, c, d = q
    expected_orient = orient2d_many(a, b, c)[0]
    if expected_orient == 0:
        with pytest.raises(ValueError):
            incircle(a, b, c, d)
        return
    got = incircle(a, b, c, d)
    assert got == exact_incircle(a, b, c, d)
    assert incircle(b, c, a, d) == got
    assert incircle(b, a, c, d) == got


@settings(max_examples=100, deadline=None)
@given(st.lists(quads, min_size=1, max_size=15))
def test_incircle_many_matches_exact(qs):
    arr = np.array(qs, dtype=float)  # (m, 4, 2)
    turn = orient2d_many(arr[:, 0], arr[:, 1], arr[:, 2])
    keep = turn != 0  # collinear a, b, c define no circle (refused below)
    if not keep.any():
        return
    arr = arr[keep]
    got = incircle_many(arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3])
    for g, q in zip(got, arr.tolist()):
        assert g == exact_incircle(*q)  # independent of the orientation


def test_incircle_many_refuses_collinear_corners():
    with pytest.raises(ValueError, match=r"collinear .* row 1"):
        incircle_many([[1, 0], [0, 0]], [[0, 1], [1, 1]], [[-1, 0], [2, 2]], [0, 0])


# ---------------------------------------------------------------------------
# delaunay
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("n, seed", [(3, 0), (4, 1), (10, 2), (100, 3), (2000, 4)])
def test_delaunay_matches_scipy_on_random_points(n, seed):
    rng = np.random.default_rng(seed)
    pts = rng.standard_normal((n, 2)) if seed % 2 else rng.random((n, 2))
    tri = delaunay(pts)
    assert triangle_set(tri) == triangle_set(Delaunay(pts).simplices)
    assert np.all(orient2d_many(pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]) > 0)
    assert tri.dtype == np.intp


@pytest.mark.parametrize("name", sorted(DATASETS))
def test_delaunay_on_named_datasets(name):
    pts = DATASETS[name]
    tri = delaunay(pts)
    assert_valid_delaunay(pts, tri)
    np.testing.assert_array_equal(delaunay(pts), tri)  # deterministic


def test_delaunay_ignores_later_duplicates():
    rng = np.random.default_rng(9)
    base = rng.random((50, 2))
    pts = np.vstack([base, base[::2], base[:5]])
    tri = delaunay(pts)
    assert tri.max() < 50  # later copies are never used
    assert triangle_set(tri) == triangle_set(delaunay(base))


def test_delaunay_square_with_duplicate_corner():
    tri = delaunay([[0, 0], [1, 0], [1, 1], [0, 1], [1, 1]])
    assert tri.shape == (2, 3) and set(tri.ravel().tolist()) == {0, 1, 2, 3}


def test_delaunay_ten_thousand_points_under_ten_seconds():
    pts = np.random.default_rng(0).random((10_000, 2))
    t0 = time.perf_counter()
    tri = delaunay(pts)
    elapsed = time.perf_counter() - t0
    assert elapsed < 10.0, f"took {elapsed:.1f} s"
    assert is_delaunay(pts, tri)


@pytest.mark.parametrize(
    "points, message",
    [
        ([[0, 0], [1, 1], [2, 2], [3, 3]], "must not be all collinear"),
        ([[0, 0], [1, 1], [0, 0]], "at least 3 distinct points; got 2 distinct among 3"),
        ([[1, 1]], "at least 3 distinct points; got 1 distinct among 1"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], r"`points` must have shape \(n, 2\); got \(3, 3\)"),
        ([[0, 0], [1, 0], [np.inf, 1]], "`points` must contain only finite values"),
    ],
)
def test_delaunay_rejects_bad_input(points, message):
    with pytest.raises(ValueError, match=message):
        delaunay(points)


small_sets = st.lists(st.tuples(st.integers(-4, 4), st.integers(-4, 4)), min_size=3, max_size=40)


@settings(max_examples=60, deadline=None)
@given(small_sets)
def test_delaunay_properties_on_integer_points(points):
    pts = np.array(points, dtype=float)
    if len(np.unique(pts, axis=0)) < 3 or convex_hull(pts).size < 3:
        with pytest.raises(ValueError):
            delaunay(pts)
        return
    assert_valid_delaunay(pts, delaunay(pts))


# ---------------------------------------------------------------------------
# is_delaunay
# ---------------------------------------------------------------------------


def _square_with_centre():
    pts = np.array([[0, 0], [2, 0], [2, 2], [0, 2], [1, 1]], dtype=float)
    tri = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    return pts, tri


def test_is_delaunay_accepts_valid_triangulations():
    pts, tri = _square_with_centre()
    assert is_delaunay(pts, tri)
    assert is_delaunay(pts, np.roll(tri, 1, axis=1))  # rotated rows
    assert is_delaunay(pts, tri[::-1])  # any row order


def test_is_delaunay_rejects_non_delaunay_edge():
    pts = np.array([[0, 0], [4, 0], [2, 1], [2, -1]], dtype=float)
    assert is_delaunay(pts, [[0, 3, 2], [3, 1, 2]])  # the short diagonal
    assert not is_delaunay(pts, [[0, 3, 1], [0, 1, 2]])  # (2, -1) is inside the other circle


@pytest.mark.parametrize(
    "change",
    ["clockwise", "missing", "duplicate", "overlap", "unused-point", "degenerate", "scipy-flip"],
)
def test_is_delaunay_rejects_invalid_triangulations(change):
    pts, tri = _square_with_centre()
    if change == "clockwise":
        tri = tri.copy()
        tri[0] = tri[0, ::-1]
    elif change == "missing":
        tri = tri[1:]
    elif change == "duplicate":
        tri = np.vstack([tri, tri[:1]])
    elif change == "overlap":
        tri = np.vstack([tri, [[0, 1, 2]]])
    elif change == "unused-point":
        pts = np.vstack([pts, [[1.5, 0.5]]])
    elif change == "degenerate":
        pts = np.vstack([pts, [[1, 0]]])
        tri = np.vstack([tri[1:], [[0, 5, 4], [5, 1, 4], [0, 1, 5]]])
    elif change == "scipy-flip":
        rng = np.random.default_rng(5)
        pts = rng.random((30, 2))
        tri = delaunay(pts)
        tri = _flip_one_interior_edge(tri)
    assert not is_delaunay(pts, tri)


def _flip_one_interior_edge(tri: np.ndarray) -> np.ndarray:
    """Replace the two triangles of one interior edge by the other diagonal."""
    edges = {}
    for k, t in enumerate(tri.tolist()):
        for i in range(3):
            edges[t[i], t[(i + 1) % 3]] = (k, t[(i + 2) % 3])
    for (u, v), (k, w) in edges.items():
        if (v, u) in edges:
            k2, z = edges[v, u]
            out = np.delete(tri, [k, k2], axis=0)
            return np.vstack([out, [[w, u, z], [z, v, w]]])
    raise AssertionError("no interior edge")


def test_is_delaunay_cocircular_either_diagonal():
    pts = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    assert is_delaunay(pts, [[0, 1, 2], [0, 2, 3]])
    assert is_delaunay(pts, [[0, 1, 3], [1, 2, 3]])


def test_is_delaunay_accepts_scipy_on_random_points():
    pts = np.random.default_rng(8).random((500, 2))
    assert is_delaunay(pts, Delaunay(pts).simplices)


def test_is_delaunay_without_triangles_is_false():
    assert not is_delaunay([[0, 0], [1, 1], [2, 2]], np.zeros((0, 3), dtype=int))


@pytest.mark.parametrize(
    "triangles, message",
    [
        ([[0, 1, 2.0]], "`triangles` must be an integer array of point indices; got dtype float64"),
        ([[0, 1]], r"`triangles` must have shape \(m, 3\); got \(1, 2\)"),
        ([[0, 1, 7]], r"`triangles` must hold indices in \[0, 3\) for 3 points"),
        ([[0, -1, 2]], r"`triangles` must hold indices in \[0, 3\)"),
    ],
)
def test_is_delaunay_rejects_bad_input(triangles, message):
    with pytest.raises(ValueError, match=message):
        is_delaunay([[0, 0], [1, 0], [0, 1]], triangles)
