"""Tests of :func:`reference.orient2d` and :func:`reference.convex_hull`: exact orientation and convex hulls.

Oracles: exact determinants with :class:`fractions.Fraction`, a plain
monotone chain over ``Fraction`` coordinates (no filter, no prefilter), and
``scipy.spatial.ConvexHull`` on inputs in general position.
"""

from __future__ import annotations

import importlib
import importlib.util
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial import ConvexHull

from reference import convex_hull, orient2d, orient2d_many

METHODS = ("monotone", "jarvis")
ULP_HALF = 2.0**-53  # spacing of doubles in [0.5, 1)

if importlib.util.find_spec("pytest_timeout") is not None:
    timeout = pytest.mark.timeout
else:  # the loop bound in the code is the real guarantee; this is a guard

    def timeout(_seconds):
        return lambda f: f


# ---------------------------------------------------------------------------
# Named datasets
# ---------------------------------------------------------------------------


def _kettner_grid(size: int = 16) -> np.ndarray:
    """Points (0.5 + k u, 0.5 + l u), u = 2**-53, near the line y = x."""
    k, l_ = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
    return np.column_stack([0.5 + k.ravel() * ULP_HALF, 0.5 + l_.ravel() * ULP_HALF])


# Kettner et al. (2008), Section 4: inputs on which the incremental hull with
# a floating-point orientation test fails (A1: an outside point sees no edge;
# A2: an inside point sees an edge; B1/B2: wrong visibility).
KETTNER = {
    "kettner-A1": [
        (7.3000000000000194, 7.3000000000000167),
        (24.000000000000068, 24.000000000000071),
        (24.00000000000005, 24.000000000000053),
        (0.50000000000001621, 0.50000000000001243),
        (8, 4), (4, 9), (15, 27), (26, 25), (19, 11),
    ],
    "kettner-A2": [
        (27.643564356435643, -21.881188118811881),
        (83.366336633663366, 15.544554455445542),
        (4.0, 4.0),
        (73.415841584158414, 8.8613861386138595),
    ],
    "kettner-A2v": [
        (24.00000000000005, 24.000000000000053),
        (24, 6),
        (54.850000000000357, 61.000000000000121),
        (24.000000000000068, 24.000000000000071),
        (6, 6),
    ],
    "kettner-B1": [
        (200.0, 49.200000000000003),
        (100.0, 49.600000000000001),
        (-233.33333333333334, 50.93333333333333),
        (166.66666666666669, 49.333333333333336),
    ],
    "kettner-B2": [
        (0.50000000000001243, 0.50000000000000189),
        (0.50000000000001243, 0.50000000000000333),
        (24.00000000000005, 24.000000000000053),
        (24.000000000000068, 24.000000000000071),
        (17.300000000000001, 17.300000000000001),
    ],
}  # fmt: skip


def _datasets() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(20240601)
    data = {name: np.array(pts, dtype=float) for name, pts in KETTNER.items()}
    grid = _kettner_grid()
    data["kettner-grid+line"] = np.vstack([grid, [[12, 12], [24, 24]]])
    data["kettner-grid+far"] = np.vstack([grid, [[24.0, 24.0], [0.25, 0.25 + 2.0**-54]]])
    g = np.arange(5.0)
    data["grid-5x5"] = np.array([(x, y) for x in g for y in g])
    data["grid-5x5-shuffled-dups"] = rng.permutation(np.vstack([data["grid-5x5"]] * 3))
    data["integers-0..3"] = rng.integers(0, 4, size=(60, 2)).astype(float)
    t = rng.random(50)
    data["near-line"] = np.column_stack([t, t + rng.integers(-3, 4, 50) * 2.0**-52])
    data["sliver"] = np.array([(0, 0), (1, 1e-12), (2, 0), (1, -1e-12), (0.5, 0), (1.5, 0)])
    data["huge"] = (rng.random((40, 2)) - 0.5) * 3e307
    data["tiny"] = rng.random((40, 2)) * 1e-310
    data["random-300"] = rng.random((300, 2))
    return data


DATASETS = _datasets()


# ---------------------------------------------------------------------------
# Oracles
# ---------------------------------------------------------------------------


def exact_orient(p, q, r) -> int:
    px, py, qx, qy, rx, ry = (Fraction(float(v)) for v in (*p, *q, *r))
    det = (qx - px) * (ry - py) - (qy - py) * (rx - px)
    return (det > 0) - (det < 0)


def exact_hull(points: np.ndarray) -> list[int]:
    """Monotone chain over Fractions: the oracle for degenerate inputs."""
    pts = [(Fraction(float(x)), Fraction(float(y))) for x, y in points]
    order = sorted(range(len(pts)), key=lambda i: (pts[i], i))
    uniq = [i for k, i in enumerate(order) if k == 0 or pts[i] != pts[order[k - 1]]]
    if len(uniq) == 1:
        return uniq

    def turn(i, j, k):
        (ax, ay), (bx, by), (cx, cy) = pts[i], pts[j], pts[k]
        return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)

    def chain(seq):
        h = []
        for i in seq:
            while len(h) >= 2 and turn(h[-2], h[-1], i) <= 0:
                h.pop()
            h.append(i)
        return h

    return chain(uniq)[:-1] + chain(uniq[::-1])[:-1]


def assert_valid_hull(points: np.ndarray, hull: np.ndarray) -> None:
    """Exact properties: start, strict convexity, containment, dtype."""
    assert hull.dtype == np.intp and hull.ndim == 1
    assert len(set(hull.tolist())) == hull.size
    lexmin = min(range(len(points)), key=lambda i: (points[i][0], points[i][1], i))
    assert hull[0] == lexmin
    h = hull.size
    if h >= 3:
        for i in range(h):
            a, b, c = points[hull[i]], points[hull[(i + 1) % h]], points[hull[(i + 2) % h]]
            assert exact_orient(a, b, c) > 0
        for i in range(h):
            a, b = points[hull[i]], points[hull[(i + 1) % h]]
            assert np.all(orient2d_many(a, b, points) >= 0), "a point lies outside the hull"


def rotate_to(seq: np.ndarray, first: int) -> np.ndarray:
    k = int(np.flatnonzero(seq == first)[0])
    return np.roll(seq, -k)


# ---------------------------------------------------------------------------
# orient2d
# ---------------------------------------------------------------------------


def test_orient2d_basic_signs():
    assert orient2d([0, 0], [1, 0], [0, 1]) == 1
    assert orient2d([0, 0], [0, 1], [1, 0]) == -1
    assert orient2d([0, 0], [1, 1], [2, 2]) == 0
    assert orient2d([1, 1], [1, 1], [5, -3]) == 0
    assert type(orient2d((0, 0), (1, 0), (0, 1))) is int


def test_orient2d_kettner_grid_is_exact():
    """sign(orient2d(p, (12, 12), (24, 24))) = sign(l - k) on the whole grid."""
    grid = _kettner_grid(64)
    k = np.rint((grid[:, 0] - 0.5) / ULP_HALF)
    l_ = np.rint((grid[:, 1] - 0.5) / ULP_HALF)
    expected = np.sign(l_ - k)
    got = orient2d_many(grid, [12.0, 12.0], [24.0, 24.0])
    np.testing.assert_array_equal(got, expected)
    # the naive formula is wrong on this grid (which is why it is a test case)
    q, r = np.array([12.0, 12.0]), np.array([24.0, 24.0])
    dq, dr = q - grid, r - grid
    naive = np.sign(dq[:, 0] * dr[:, 1] - dq[:, 1] * dr[:, 0])
    assert np.any(naive != expected)
    for i in range(0, grid.shape[0], 97):
        assert orient2d(grid[i], q, r) == expected[i]


@pytest.mark.parametrize(
    "p, q, r",
    [
        ((1e308, -1e308), (-1e308, 1e308), (0.0, 0.0)),  # differences overflow
        ((1e308, 1e308), (-1e308, -1e308), (1.7e308, 1.7e308)),
        ((5e-324, 0.0), (0.0, 5e-324), (0.0, 0.0)),  # products underflow
        ((1e-200, 1e-200), (3e-200, 3e-200), (2e-200, 2e-200 + 1e-215)),
        ((0.1, 0.1), (0.2, 0.2), (0.3, 0.3)),
    ],
)
def test_orient2d_extreme_magnitudes(p, q, r):
    assert orient2d(p, q, r) == exact_orient(p, q, r)


@pytest.mark.parametrize(
    "args, message",
    [
        (([0, 0, 0], [1, 0], [0, 1]), "`p` must be a point of shape (2,)"),
        (([0, 0], [[1, 0]], [0, 1]), "`q` must be a point of shape (2,)"),
        (([0, 0], [1, 0], [np.nan, 1]), "`r` must contain only finite values"),
        (([np.inf, 0], [1, 0], [0, 1]), "`p` must contain only finite values"),
        (([0, 0], ["a", 0], [0, 1]), "`q` must be an array of real numbers"),
    ],
)
def test_orient2d_rejects_bad_input(args, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        orient2d(*args)


finite = st.floats(allow_nan=False, allow_infinity=False)
small_offsets = st.integers(-4, 4)


@st.composite
def near_collinear_triples(draw):
    """Three points within a few ulps of the line y = x, at several scales."""
    base = draw(st.sampled_from([0.5, 1.0, 3.0, 1e10, 1e-10]))
    line = [base * (1 + draw(st.integers(0, 5))) for _ in range(3)]
    out = []
    for x, y in zip(line, line):
        out.append((np.nextafter(x, np.inf) if draw(st.booleans()) else x,
                    y + draw(small_offsets) * np.spacing(y)))  # fmt: skip
    return out


triples = st.one_of(
    st.tuples(*[st.tuples(finite, finite)] * 3),
    near_collinear_triples(),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(triples)
def test_orient2d_matches_fraction_determinant(t):
    p, q, r = t
    assert orient2d(p, q, r) == exact_orient(p, q, r)


@settings(max_examples=200, deadline=None)
@given(triples)
def test_orient2d_antisymmetric_and_cyclic(t):
    p, q, r = t
    s = orient2d(p, q, r)
    assert orient2d(q, p, r) == -s
    assert orient2d(p, r, q) == -s
    assert orient2d(q, r, p) == s
    assert orient2d(r, p, q) == s


@settings(max_examples=100, deadline=None)
@given(st.lists(triples, min_size=1, max_size=20))
def test_orient2d_many_matches_scalar(ts):
    arr = np.array(ts, dtype=float)  # (m, 3, 2)
    got = orient2d_many(arr[:, 0], arr[:, 1], arr[:, 2])
    assert got.tolist() == [orient2d(*t) for t in ts]


# ---------------------------------------------------------------------------
# convex_hull
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("n, seed", [(3, 0), (10, 1), (100, 2), (1000, 3), (20000, 4)])
def test_hull_matches_scipy_on_random_points(method, n, seed):
    rng = np.random.default_rng(seed)
    pts = rng.standard_normal((n, 2)) if seed % 2 else rng.random((n, 2))
    hull = convex_hull(pts, method=method)
    expected = ConvexHull(pts).vertices  # counter-clockwise in 2-D
    np.testing.assert_array_equal(hull, rotate_to(expected, hull[0]))
    assert hull.dtype == np.intp


@pytest.mark.parametrize("method", METHODS)
def test_hull_matches_scipy_on_points_of_a_circle(method):
    rng = np.random.default_rng(7)
    angle = np.sort(rng.random(3000)) * 2 * np.pi
    pts = np.column_stack([np.cos(angle), np.sin(angle)]) * 100
    hull = convex_hull(pts, method=method)
    np.testing.assert_array_equal(hull, rotate_to(ConvexHull(pts).vertices, hull[0]))


@pytest.mark.parametrize("name", sorted(DATASETS))
@pytest.mark.parametrize("method", METHODS)
def test_hull_on_named_datasets_matches_exact_oracle(name, method):
    pts = DATASETS[name]
    hull = convex_hull(pts, method=method)
    assert hull.tolist() == exact_hull(pts)
    assert_valid_hull(pts, hull)


@pytest.mark.parametrize("method", METHODS)
def test_hull_of_grid_skips_collinear_points(method):
    pts = DATASETS["grid-5x5"]  # index 5 * x + y
    assert convex_hull(pts, method=method).tolist() == [0, 20, 24, 4]


@pytest.mark.parametrize("method", METHODS)
def test_hull_duplicates_use_smallest_index(method):
    pts = [[1, 1], [0, 0], [1, 0], [0, 0], [1, 1], [0, 1], [1, 0], [0.5, 0.5]]
    assert convex_hull(pts, method=method).tolist() == [1, 2, 0, 5]


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize(
    "pts, expected",
    [
        ([[3.0, 4.0]], [0]),
        ([[3.0, 4.0]] * 5, [0]),
        ([[1, 1], [0, 0]], [1, 0]),
        ([[2, 2], [0, 0], [1, 1], [3, 3], [0, 0]], [1, 3]),
        ([[0, 2], [0, 0], [0, 1], [0, -1]], [3, 0]),  # vertical line
        ([[1, 5], [0, 5], [2, 5], [1, 5]], [1, 2]),  # horizontal line
    ],
)
def test_hull_degenerate_inputs(method, pts, expected):
    assert convex_hull(pts, method=method).tolist() == expected


@timeout(30)
@pytest.mark.parametrize("method", METHODS)
def test_jarvis_terminates_on_near_collinear_points(method):
    """The float textbook march loops forever on these; ours is exact and bounded."""
    rng = np.random.default_rng(11)
    t = np.sort(rng.random(400)) * 24
    pts = np.column_stack([t, t])
    pts[:, 1] += rng.integers(-2, 3, size=t.size) * np.spacing(pts[:, 1])
    pts = np.vstack([pts, _kettner_grid(8), [[12, 12], [24, 24]]])
    hull = convex_hull(pts, method=method)
    assert hull.tolist() == exact_hull(pts)


@pytest.mark.parametrize("method", METHODS)
def test_hull_akl_toussaint_on_large_degenerate_input(method):
    """Many points on the hull boundary and many exact duplicates."""
    rng = np.random.default_rng(3)
    square = rng.integers(0, 50, size=(5000, 2)).astype(float)
    border = np.array([(x, y) for x in (0.0, 49.0) for y in range(50)])
    pts = np.vstack([square, border, border])
    hull = convex_hull(pts, method=method)
    corners = [(0.0, 0.0), (49.0, 0.0), (49.0, 49.0), (0.0, 49.0)]
    first = [int(np.flatnonzero((pts == c).all(axis=1))[0]) for c in corners]
    assert hull.tolist() == first


grid_points = st.lists(st.tuples(st.integers(-3, 3), st.integers(-3, 3)), min_size=1, max_size=40)
float_points = st.lists(st.tuples(finite, finite), min_size=1, max_size=25)


@settings(max_examples=150, deadline=None)
@given(st.one_of(grid_points, float_points))
def test_hull_properties(points):
    pts = np.array(points, dtype=float)
    hulls = [convex_hull(pts, method=m) for m in METHODS]
    np.testing.assert_array_equal(hulls[0], hulls[1])
    assert_valid_hull(pts, hulls[0])
    assert hulls[0].tolist() == exact_hull(pts)


@pytest.mark.parametrize(
    "points, kwargs, message",
    [
        ([[0, 0, 0], [1, 1, 1]], {}, r"`points` must have shape \(n, 2\); got \(2, 3\)\."),
        ([0, 1], {}, r"`points` must have shape \(n, 2\); got \(2,\)\."),
        (np.zeros((0, 2)), {}, r"`points` must hold at least 1 point\(s\); got 0\."),
        ([[0, np.nan]], {}, r"`points` must contain only finite values"),
        ([[0, 0]], {"method": "graham"},
         r"`method` must be one of 'jarvis', 'monotone'; got 'graham'\."),  # fmt: skip
    ],
)
def test_hull_rejects_bad_input(points, kwargs, message):
    with pytest.raises(ValueError, match=message):
        convex_hull(points, **kwargs)
