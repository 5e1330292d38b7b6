"""Hidden checks for the Delaunay assignment: the real grading.

in_circle: exact answers on cocircular points (a point on the circle is not
strictly inside) and on points a few units in the last place (ulps) off a
circle, where the floating-point determinant has the wrong sign.

delaunay: named point sets. Where no four points are cocircular the Delaunay
triangulation is unique: the answer is compared, as a set of triangles, with
``reference.delaunay`` (exact arithmetic), itself cross-checked with
``scipy.spatial.Delaunay``. Where points are cocircular (grid, circle) many
triangulations are valid, so the answer is judged by its properties, all
tested exactly: counter-clockwise non-degenerate triangles, 2n - 2 - h of
them, covering the convex hull, every interior edge locally Delaunay (which
makes every circumcircle empty), and ``reference.is_delaunay`` as the
final word. Sets named ``random-*`` and ``unseen-*`` are drawn from the ``rng``
fixture: a regrade draws the same points, another submission draws others.

plot_on_mesh: the figure must fill the mesh with colours spanning the values.

References
----------
J. R. Shewchuk, "Adaptive precision floating-point arithmetic and fast robust
geometric predicates", Discrete & Computational Geometry 18, 305-363, 1997.
doi:10.1007/PL00009321
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial import Delaunay

import delaunay_feedback as fb  # checks/public/delaunay_feedback.py: on sys.path while checks run
from autograder.checks import (
    Broken,
    CheckFailure,
    Credit,
    Dataset,
    Feedback,
    Student,
    over_datasets,
    sentence,
    show_point,
)
from reference import delaunay, incircle, incircle_many, is_delaunay, orient2d_many

Point = tuple[float, float]
#: (a, b, c, d) with a, b, c counter-clockwise
Quad = tuple[Point, Point, Point, Point]

LAKE_CSV = Path(__file__).resolve().parents[2] / "data" / "lake.csv"
#: a UTM-like origin (metres): large coordinates, small differences
UTM_ORIGIN = np.array([512_000.0, 5_270_000.0])
EXACT_HINT = ("These points are within a few units in the last place of one circle: a "
              "floating-point determinant can have the wrong sign here, so compute it "
              "exactly (Fraction).")


# ---------------------------------------------------------------------------
# in_circle cases: (a, b, c, d) with a, b, c counter-clockwise
# ---------------------------------------------------------------------------

def _integer_circle(r: int) -> list[tuple[int, int]]:
    """Every integer point on the circle of radius ``r``, counter-clockwise from angle -pi."""
    pts = [(x, y) for x in range(-r, r + 1) for y in range(-r, r + 1) if x * x + y * y == r * r]
    return sorted(pts, key=lambda p: np.arctan2(p[1], p[0]))


CIRCLE_65 = _integer_circle(65)  # 36 points: exactly cocircular integers


def _float_inside(a: Point, b: Point, c: Point, d: Point) -> bool:
    """The textbook determinant (translated to d) in floating point: what the checks fool."""
    (ax_, ay_), (bx_, by_), (cx_, cy_) = ((p[0] - d[0], p[1] - d[1]) for p in (a, b, c))
    det = ((ax_ * ax_ + ay_ * ay_) * (bx_ * cy_ - cx_ * by_)
           + (bx_ * bx_ + by_ * by_) * (cx_ * ay_ - ax_ * cy_)
           + (cx_ * cx_ + cy_ * cy_) * (ax_ * by_ - bx_ * ay_))
    return bool(det > 0)


def _ccw(a: Point, b: Point, c: Point) -> tuple[Point, Point, Point]:
    return (a, b, c) if orient2d_many(a, b, c)[0] > 0 else (a, c, b)


def _integer_cases(rng: np.random.Generator) -> list[Quad]:
    """Small integer points: random quadruples, and quadruples on the circle of radius 5."""
    g = np.random.default_rng(501)
    cases: list[Quad] = []
    while len(cases) < 8:
        a, b, c, d = (tuple(int(v) for v in g.integers(-6, 7, 2)) for _ in range(4))
        if orient2d_many(a, b, c)[0] != 0 and d not in (a, b, c):
            cases.append((*_ccw(a, b, c), d))
    ring = _integer_circle(5)
    for i, j, k, m in [(0, 3, 6, 9), (1, 2, 7, 11), (4, 5, 10, 0)]:
        cases.append((ring[i], ring[j], ring[k], ring[m]))
    return cases


def _shift(p: Point, scale: float = 0.125,
           origin: Point = (2.0**20 + 0.5, -(2.0**19) + 0.25)) -> Point:
    return (origin[0] + scale * p[0], origin[1] + scale * p[1])


def _cocircular_shifted(rng: np.random.Generator) -> list[Quad]:
    """Points exactly on one circle far from the origin (every coordinate exact in binary)."""
    g = np.random.default_rng(65)
    cases: list[Quad] = []
    for _ in range(6):
        i, j, k, m = g.choice(len(CIRCLE_65), 4, replace=False)
        a, b, c = (CIRCLE_65[v] for v in sorted((i, j, k)))  # sorted by angle: ccw
        cases.append(tuple(_shift(p) for p in (a, b, c, CIRCLE_65[m])))
    a, b, c = CIRCLE_65[2], CIRCLE_65[14], CIRCLE_65[27]
    for d in [(0, 0), (10, -7), (60, 40), (-50, -45)]:  # two inside, two outside
        cases.append(tuple(_shift(p) for p in (a, b, c, d)))
    return cases


def _nudged_circle_cases(g: np.random.Generator, count: int,
                         fooled: Callable[[Point, Point, Point, Point], bool]) -> list[Quad]:
    """Points of CIRCLE_65 / 8, with d moved 1-3 ulps: the float sign is wrong for each."""
    cases: list[Quad] = []
    for _ in range(50000):
        idx = np.sort(g.choice(len(CIRCLE_65), 4, replace=False))
        k = int(g.integers(4))
        a, b, c = (tuple(v / 8 for v in CIRCLE_65[i]) for i in np.delete(idx, k))
        d = [v / 8 for v in CIRCLE_65[idx[k]]]
        j, steps = int(g.integers(2)), int(g.choice([-3, -2, -1, 1, 2, 3]))
        if d[j] == 0:
            continue
        d[j] += steps * float(np.spacing(d[j]))
        d = tuple(d)
        if fooled(a, b, c, d):
            cases.append((a, b, c, d))
            if len(cases) == count:
                break
    return cases


def _near_cocircular_ulp(rng: np.random.Generator) -> list[Quad]:
    u = 2.0**-53
    unit: list[Quad] = [
        ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0 + u)),       # one ulp inside
        ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0 - 2 * u))]   # one ulp outside
    g = np.random.default_rng(4225)
    return unit + _nudged_circle_cases(
        g, 8, lambda a, b, c, d: _float_inside(a, b, c, d) != (incircle(a, b, c, d) > 0))


def _unseen_near_cocircular(rng: np.random.Generator, count: int = 8) -> list[Quad]:
    """Random circles; d a few ulps from the circle through a, b, c; float sign wrong."""
    cases: list[Quad] = []
    for _ in range(40000):
        centre = rng.uniform(-10, 10, 2)
        radius = 10.0 ** rng.uniform(-1, 1.5)
        angles = np.sort(rng.uniform(-np.pi, np.pi, 4))
        ring = centre + radius * np.c_[np.cos(angles), np.sin(angles)]
        k = int(rng.integers(4))
        a, b, c = (tuple(float(v) for v in ring[i]) for i in range(4) if i != k)
        if orient2d_many(a, b, c)[0] <= 0:
            continue
        d = ring[k].copy()
        j = int(rng.integers(2))
        d[j] += int(rng.integers(-4, 5)) * np.spacing(d[j])
        d = tuple(float(v) for v in d)
        if _float_inside(a, b, c, d) != (incircle(a, b, c, d) > 0):
            cases.append((a, b, c, d))
            if len(cases) == count:
                break
    a, b, c = cases[0][:3] if cases else ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0))
    middle = tuple((np.array(a) + np.array(b) + np.array(c)) / 3)
    far = tuple(np.array(a) + 10 * (np.array(a) - np.array(middle)))
    return cases + [(a, b, c, middle), (a, b, c, far)]


#: exact answers: no tolerance anywhere
CIRCLE_CASES: dict[str, Dataset[list[Quad]]] = {
    "integer-cases": Dataset(_integer_cases),
    "cocircular-shifted": Dataset(
        _cocircular_shifted,
        hint="These points are exactly on one circle, far from the origin: subtract d before "
             "squaring, and compute exactly."),
    "near-cocircular-ulp": Dataset(_near_cocircular_ulp, points=2, hint=EXACT_HINT),
    "unseen-near-cocircular": Dataset(_unseen_near_cocircular, points=2, hint=EXACT_HINT),
}


@over_datasets(CIRCLE_CASES)
def test_in_circle(student: Student, credit: Credit, rng: np.random.Generator,
                   name: str) -> None:
    dataset = CIRCLE_CASES[name]
    quads = [tuple(quad) for quad in dataset.build(rng)]  # (a, b, c, d): one call each
    cases: list[tuple[Quad, object, int]] = [
        (quad, got, incircle(*quad)) for quad, got in zip(quads, student.map("in_circle", quads))]
    fb.judge_in_circle(cases, hint=dataset.hint, credit=credit)


# ---------------------------------------------------------------------------
# point sets
# ---------------------------------------------------------------------------

def _random_box(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` uniform points in a box of random place, size and shape."""
    width = rng.uniform(1.0, 50.0)
    size = np.array([width, width * rng.uniform(0.5, 2.0)])
    return rng.uniform(-100.0, 100.0, 2) + size * rng.uniform(size=(n, 2))


def _grid_6x6(rng: np.random.Generator) -> np.ndarray:
    xy = np.array([(x, y) for x in range(6) for y in range(6)], dtype=float)
    return np.random.default_rng(66).permutation(xy) * 0.5 + [-1.0, 2.0]


def _circle_20(rng: np.random.Generator) -> np.ndarray:
    """20 of the integer points of radius 65, scaled by 1/8 and moved: exactly cocircular."""
    g = np.random.default_rng(20)
    pts = np.array([CIRCLE_65[i] for i in g.choice(len(CIRCLE_65), 20, replace=False)], float)
    return pts / 8 + [4096.5, -1024.25]


def _sliver(rng: np.random.Generator) -> np.ndarray:
    """A lens 1 long and 2e-5 thick: thin triangles, and hull triangles whose
    circumcircles are hundreds of times wider than the points."""
    g = np.random.default_rng(5)
    xt, xb = np.sort(g.uniform(0, 1, 20)), np.sort(g.uniform(0, 1, 20))
    h = 1e-5
    top = np.c_[xt, h * (1 - (2 * xt - 1) ** 2)]
    bottom = np.c_[xb, -h * (1 - (2 * xb - 1) ** 2)]
    return g.permutation(np.vstack([top, bottom, [[0.0, 0.0], [1.0, 0.0]]]))


def _clustered(rng: np.random.Generator) -> np.ndarray:
    """Gaussian clusters of very different sizes and spreads."""
    g = np.random.default_rng(31)
    parts = [g.uniform(-10, 10, 2) + 10.0 ** g.uniform(-3, 0) * g.standard_normal(
        (int(g.integers(20, 80)), 2)) for _ in range(5)]
    return g.permutation(np.vstack(parts))


def _lake_utm(rng: np.random.Generator) -> np.ndarray:
    """data/lake.csv in UTM-like coordinates, in another order."""
    lake = np.loadtxt(LAKE_CSV, delimiter=",", skiprows=1)
    return np.random.default_rng(8).permutation(lake) + UTM_ORIGIN


#: exact predicates: no tolerance anywhere
DATASETS: dict[str, Dataset[np.ndarray]] = {
    # the same 50 points for everyone: on 50 points whether a too-small super-triangle
    # loses a hull triangle is chance (1 student in 4 got it right with other data);
    # the larger random sets and "unseen-random" below carry the unseen data
    "random-50": Dataset(lambda rng: _random_box(np.random.default_rng(50), 50), points=2),
    "random-500": Dataset(lambda rng: _random_box(rng, 500), points=2),
    "random-2000": Dataset(lambda rng: _random_box(rng, 2000), points=2),
    "grid-6x6": Dataset(_grid_6x6, points=2),
    "circle-20": Dataset(_circle_20, points=2),
    "sliver": Dataset(_sliver, points=2),
    "clustered": Dataset(_clustered, points=2),
    "lake-utm": Dataset(_lake_utm),
}
#: many points cocircular: many valid answers, judged by their properties; elsewhere no
#: four points are cocircular, the answer is unique and scipy must agree
COCIRCULAR = {"grid-6x6", "circle-20"}


# ---------------------------------------------------------------------------
# the exact judge
# ---------------------------------------------------------------------------

def _sorted_set(tri: np.ndarray) -> set[tuple[int, ...]]:
    return {tuple(t) for t in np.sort(np.asarray(tri), axis=1).tolist()}


def _interior_pairs(tri: np.ndarray) -> np.ndarray:
    """For each interior edge u -> v of triangle k (apex w), the apex z across it."""
    edge_of: dict[tuple[int, int], tuple[int, int]] = {}
    for k, t in enumerate(tri.tolist()):
        for i in range(3):
            edge_of[t[i], t[(i + 1) % 3]] = (k, t[(i + 2) % 3])
    rows = [(u, v, w, edge_of[v, u][1], k) for (u, v), (k, w) in edge_of.items()
            if (v, u) in edge_of and u < v]
    return np.array(rows, dtype=np.int64).reshape(-1, 5)


def oracle(points: np.ndarray, *, general: bool) -> np.ndarray:
    """The exact Delaunay triangulation; cross-checked with scipy when it is unique."""
    expected = delaunay(points)
    if general:
        pairs = _interior_pairs(expected)
        p = points
        signs = incircle_many(p[pairs[:, 0]], p[pairs[:, 1]], p[pairs[:, 2]], p[pairs[:, 3]])
        if np.any(signs == 0) or _sorted_set(expected) != _sorted_set(Delaunay(points).simplices):
            raise RuntimeError("reference.delaunay and scipy.spatial.Delaunay disagree, or the "
                               "set has cocircular points: fix the dataset or its flag.")
    return expected


def _missing_near_hull(fixed: np.ndarray, expected: np.ndarray) -> bool | None:
    """When the answer is part of the expected triangulation: True if every missing
    triangle is joined to a hull edge through missing triangles (a super-triangle that
    is too small), False if some are enclosed (a hole); None when it is not a part."""
    got, want = _sorted_set(fixed), _sorted_set(expected)
    missing = want - got
    if not missing or not got <= want:
        return None
    hull = {frozenset(e) for e in fb.boundary_edges(expected)}
    by_edge: dict[frozenset[int], list[tuple[int, ...]]] = {}
    for t in missing:
        for i in range(3):
            by_edge.setdefault(frozenset((t[i], t[(i + 1) % 3])), []).append(t)
    todo = [t for t in missing
            if any(frozenset((t[i], t[(i + 1) % 3])) in hull for i in range(3))]
    reached = set(todo)
    while todo:
        t = todo.pop()
        for i in range(3):
            for s in by_edge[frozenset((t[i], t[(i + 1) % 3]))]:
                if s not in reached:
                    reached.add(s)
                    todo.append(s)
    return reached == missing


def exact_judge(points: np.ndarray, expected: np.ndarray, *, general: bool) -> fb.Judge:
    """A judge (see the feedback module) using exact predicates only."""
    n = len(points)
    hull = len(fb.boundary_edges(expected))

    def judge(tri: np.ndarray, broken: Broken) -> None:
        fb.check_indices(tri, n)
        p = points
        turn = orient2d_many(p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]])
        flat = np.flatnonzero(turn == 0)
        if flat.size:
            k = int(flat[0])
            raise CheckFailure(f"Triangle {k} {fb.show_triangle(tri[k])} is flat: its three "
                               "points lie on one line, so it has no circumcircle.")
        clockwise = np.flatnonzero(turn < 0)
        fixed = tri.copy()
        fixed[clockwise] = fixed[clockwise][:, [0, 2, 1]]
        _check_overlaps(tri, fixed)
        _check_coverage(points, tri, fixed, expected, hull)
        _check_empty_circles(points, tri, fixed)
        differs = general and _sorted_set(fixed) != _sorted_set(expected)
        if differs or not is_delaunay(points, fixed):
            raise CheckFailure("Your triangles do not form the Delaunay triangulation of the "
                               "points (they overlap or leave gaps).")
        if clockwise.size:
            broken.note("clockwise", fb.clockwise_note(tri, clockwise.tolist()))

    return judge


def _check_overlaps(tri: np.ndarray, fixed: np.ndarray) -> None:
    owner: dict[tuple[int, int], int] = {}
    for k, t in enumerate(fixed.tolist()):
        for i in range(3):
            e = (t[i], t[(i + 1) % 3])
            j = owner.setdefault(e, k)
            if j != k:
                raise CheckFailure(
                    f"Triangles {j} {fb.show_triangle(tri[j])} and {k} {fb.show_triangle(tri[k])} "
                    f"overlap: both lie on the same side of their common edge ({e[0]}, {e[1]}).")


def _check_coverage(points: np.ndarray, tri: np.ndarray, fixed: np.ndarray,
                    expected: np.ndarray, hull: int) -> None:
    """Fail unless the triangles use every point and fill the convex hull."""
    n, m, count = len(points), len(tri), len(expected)
    unused = sorted(set(range(n)) - set(fixed.ravel().tolist()))
    beyond = None
    for u, v in fb.boundary_edges(fixed):
        out = np.flatnonzero(orient2d_many(points[u], points[v], points) < 0)
        if out.size:
            beyond = (u, v, int(out[0]))
            break
    if not unused and beyond is None and m == count:
        return
    parts = [fb.count_message(count, n, hull, m)] if m != count else []
    inside = _vertex_inside(points, fixed) if m > count else None
    if inside is not None:
        q, k = inside
        raise CheckFailure(sentence(
            f"{parts[0]}: point {q} lies strictly inside triangle {k} "
            f"{fb.show_triangle(tri[k])}, so some triangles overlap"))
    near_hull = _missing_near_hull(fixed, expected)
    if near_hull is False:
        hull_edges = set(fb.boundary_edges(expected))
        u, v = next(e for e in fb.boundary_edges(fixed) if e not in hull_edges)
        parts.append(f"your mesh has a hole: the edge ({u}, {v}) inside the hull has a "
                     "triangle on one side only")
    elif beyond is not None:
        u, v, q = beyond
        if near_hull:
            parts.append(f"the triangles along the hull are missing ({fb.SUPER_HINT}); "
                         f"point {q} at {show_point(points[q])} lies outside your mesh, "
                         f"beyond its edge ({u}, {v})")
        else:
            parts.append(f"point {q} at {show_point(points[q])} lies beyond the edge "
                         f"({u}, {v}), which has a triangle on one side only: the mesh "
                         "does not fill the convex hull")
    elif near_hull:
        parts.append(f"the triangles along the hull are missing ({fb.SUPER_HINT})")
    if unused:
        q = unused[0]
        parts.append(f"point {q} at {show_point(points[q])} is a corner of no triangle"
                     + (f" ({len(unused)} points are unused)" if len(unused) > 1 else ""))
    if m > count and near_hull is None and beyond is None and not unused:
        parts.append("some triangles overlap")
    text = parts[0] + (": " + "; ".join(parts[1:]) if len(parts) > 1 else "")
    raise CheckFailure(sentence(text))


def _vertex_inside(points: np.ndarray, fixed: np.ndarray,
                   limit: int = 5000) -> tuple[int, int] | None:
    """``(q, k)``: a point strictly inside counter-clockwise triangle ``k`` (exact), or None."""
    corners = points[fixed]
    low, high = corners.min(axis=1), corners.max(axis=1)
    for k in range(min(len(fixed), limit)):
        near = np.flatnonzero(np.all((points > low[k]) & (points < high[k]), axis=1))
        if near.size == 0:
            continue
        a, b, c = corners[k]
        q = points[near]
        strictly = ((orient2d_many(a, b, q) > 0) & (orient2d_many(b, c, q) > 0)
                    & (orient2d_many(c, a, q) > 0))
        if strictly.any():
            return int(near[np.argmax(strictly)]), k
    return None


def _check_empty_circles(points: np.ndarray, tri: np.ndarray, fixed: np.ndarray) -> None:
    """Fail at the first interior edge that is not locally Delaunay (exact)."""
    pairs = _interior_pairs(fixed)
    if len(pairs) == 0:
        return
    p = points
    inside = incircle_many(p[pairs[:, 0]], p[pairs[:, 1]], p[pairs[:, 2]], p[pairs[:, 3]]) > 0
    if inside.any():
        u, v, _, z, k = (int(x) for x in pairs[np.argmax(inside)])
        raise CheckFailure(
            f"Point {z} lies strictly inside the circumcircle of triangle {k} "
            f"{fb.show_triangle(tri[k])}, so that triangle is not Delaunay (flip the edge "
            f"({u}, {v}): the triangles on either side of it should be replaced).")


@over_datasets(DATASETS)
def test_delaunay(student: Student, credit: Credit, rng: np.random.Generator,
                  name: str) -> None:
    points = DATASETS[name].build(rng)
    general = name not in COCIRCULAR
    expected = oracle(points, general=general)
    got = student.delaunay(points)
    judge = exact_judge(points, expected, general=general)
    fb.grade_triangulation(got, len(points), judge, credit)


# ---------------------------------------------------------------------------
# plotting on the mesh
# ---------------------------------------------------------------------------

def _unseen_field(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random points in a random box, and a smooth function with a random range."""
    points = _random_box(rng, int(rng.integers(80, 200)))
    z = (points - points.min(axis=0)) / np.ptp(points, axis=0)
    k = rng.uniform(1.0, 3.0, 2)
    wave = np.sin(k[0] * np.pi * z[:, 0]) * np.cos(k[1] * np.pi * z[:, 1])
    return points, rng.uniform(-50, 50) + rng.uniform(1, 100) * wave


def _far_values(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The lake with values in a narrow band far from 0 (a colour scale fixed to [0, 1] fails)."""
    points = np.loadtxt(LAKE_CSV, delimiter=",", skiprows=1)
    x, y = points[:, 0], points[:, 1]
    return points, 1013.0 + 0.02 * np.hypot(x - 400.0, y - 320.0) / 300.0


#: (points, values u at the points); the colour range tolerance is COLOUR_RANGE_TOL
FIELDS: dict[str, Dataset[tuple[np.ndarray, np.ndarray]]] = {
    "unseen-random": Dataset(_unseen_field, points=2),
    "far-values": Dataset(_far_values),
}


@over_datasets(FIELDS)
def test_plot_on_mesh(student: Student, credit: Credit, feedback: Feedback,
                      rng: np.random.Generator, name: str) -> None:
    points, u = FIELDS[name].build(rng)
    fb.grade_figure(student, points, delaunay(points), u, credit, feedback)
