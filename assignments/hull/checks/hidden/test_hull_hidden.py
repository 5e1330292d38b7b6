"""Hidden checks for the convex-hull assignment: the real grading.

Orientation: exact signs on nearly collinear triples where the plain float
determinant gets the sign wrong (Kettner et al. 2008), on scaled triangles, and
the symmetry rules (cycling keeps the sign, swapping flips it).

Convex hull: named point sets, compared with ``reference.convex_hull`` (exact
arithmetic). The hull of exact coordinates is unique, so the comparison is
exact: no tolerance anywhere in this file. Where the set is well conditioned
the oracle is also cross-checked with ``scipy.spatial.ConvexHull``.
Sets named ``unseen-*`` are drawn from the ``rng`` fixture: a regrade draws
the same points, another submission draws others.

The student's own board: ``pins`` is drawn per student (``variants.py``); the
check calls ``convex_hull`` on the student's pins, computes the expected hull
here from ``reference`` and records the answer, so a hull that is a
classmate's answer rather than the student's own is seen.

References
----------
L. Kettner, K. Mehlhorn, S. Pion, S. Schirra, C. Yap, "Classroom examples of
robustness problems in geometric computations", Computational Geometry 40(1),
61-78, 2008. doi:10.1016/j.comgeo.2007.06.003
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

import hull_feedback  # checks/public/hull_feedback.py: on sys.path while checks run
import hull_feedback as feedback  # the short name, where no check takes the `feedback` fixture
from autograder.checks import (Credit, Dataset, Feedback, Student, VariantView, over_datasets,
                               same_cycle)
from reference import convex_hull as reference_hull, orient2d

Point = tuple[float, float]
Triple = tuple[Point, Point, Point]

U = 2.0**-53  # the gap between neighbouring doubles in [0.5, 1)
NEAR_COLLINEAR_HINT = ("These points are nearly collinear: a floating-point determinant can "
                       "have the wrong sign here, so compute it exactly.")

# ---------------------------------------------------------------------------
# orientation triples
# ---------------------------------------------------------------------------

#: Kettner-style triples: p a few ulps from (0.5, 0.5), q and r a few ulps from the
#: diagonal. Found by a search in which the float determinant (pivot p) has the
#: wrong sign; most also fool the pivots q and r, the expanded 3 x 3 formula and
#: numpy.linalg.det. Decimal literals round-trip exactly.
KETTNER_TRIPLES: list[Triple] = [
    ((0.5000000000000204, 0.5000000000000064), (12.000000000000005, 11.999999999999998),
     (24.00000000000001, 24.00000000000001)),
    ((0.50000000000001, 0.500000000000024), (12.000000000000005, 12.000000000000005),
     (24.00000000000001, 23.999999999999996)),
    ((0.5000000000000063, 0.5000000000000239), (11.999999999999998, 12.000000000000002),
     (24.0, 23.99999999999999)),
    ((0.5000000000000049, 0.5000000000000061), (17.299999999999997, 17.29999999999999),
     (24.000000000000053, 24.000000000000043)),
    ((0.5000000000000132, 0.5000000000000049), (17.300000000000004, 17.300000000000004),
     (24.00000000000005, 24.000000000000053)),
    ((0.5000000000000188, 0.5000000000000129), (17.300000000000004, 17.29999999999999),
     (24.000000000000064, 24.000000000000046)),
    ((0.5000000000000171, 0.5000000000000149), (8.799999999999999, 8.800000000000002),
     (24.099999999999994, 24.10000000000001)),
    ((0.5000000000000241, 0.5000000000000201), (8.800000000000008, 8.800000000000002),
     (24.099999999999998, 24.09999999999999)),
    ((0.5000000000000027, 0.5000000000000105), (8.800000000000002, 8.800000000000008),
     (24.09999999999999, 24.09999999999999)),
    ((0.5000000000000094, 0.5000000000000084), (12.0, 12.0), (24.0, 24.0)),
    ((0.5000000000000082, 0.5000000000000092), (12.0, 12.0), (24.0, 24.0)),
    ((0.5000000000000093, 0.5000000000000081), (12.0, 12.0), (24.0, 24.0)),
]


def _integer_turns(rng: np.random.Generator) -> list[Triple]:
    return [((0, 0), (4, 0), (4, 3)), ((4, 3), (4, 0), (0, 0)), ((0, 0), (2, 2), (5, 5)),
            ((-3, 7), (2, -1), (-8, 15)), ((10, -4), (10, 9), (10, 2)),
            ((6, 6), (6, 6), (1, 2)), ((1, 2), (3, 1), (2, 4)), ((1, 2), (2, 4), (3, 1))]


def _float_collinear(rng: np.random.Generator) -> list[Triple]:
    xs = [0.1, 0.3, 0.7, 1.9, 2.65]
    on_y_eq_x = [(x, x) for x in xs]
    on_y_eq_2x = [(x, 2 * x) for x in xs]          # doubling a double is exact
    on_x_const = [(0.1, y) for y in xs]
    return [(a[0], a[2], a[4]) for a in (on_y_eq_x, on_y_eq_2x, on_x_const)] + [
        ((0.1, 0.2), (0.7, 1.4), (0.3, 0.6)), ((0.3, 0.3), (0.1, 0.1), (2.65, 2.65)),
        ((0.1, 0.1), (0.3, 0.30000000000000004), (0.7, 0.7))]


def _kettner_ulp(rng: np.random.Generator) -> list[Triple]:
    return KETTNER_TRIPLES


def _scaled_triangles(rng: np.random.Generator) -> list[Triple]:
    """Well-shaped triangles, shrunk or blown up: no tolerance can fit every scale."""
    base = [((0.0, 0.0), (3.0, 1.0), (1.0, 2.0)), ((0.0, 0.0), (1.0, 2.0), (3.0, 1.0)),
            ((1.0, 1.0), (2.0, 2.0), (4.0, 4.0))]
    out: list[Triple] = []
    for scale in (1e-9, 1e-170, 1e170):
        out += [tuple((x * scale, y * scale) for x, y in tri) for tri in base]
    return out


def _unseen_near_collinear(rng: np.random.Generator, count: int = 10) -> list[Triple]:
    """Random lines anywhere in [-1000, 1000]^2, p a few ulps off: float signs go wrong."""
    found: list[Triple] = []
    for _ in range(20000):
        a, b = rng.uniform(-1000, 1000, 2), rng.uniform(-1000, 1000, 2)
        t = rng.uniform(1.5, 3.0)
        r = tuple(float(v) for v in a + t * (b - a))
        wiggle = rng.integers(-3, 4, 2) * np.spacing(np.abs(a))
        p = tuple(float(v) for v in a + wiggle)
        q = tuple(float(v) for v in b)
        if _float_sign(p, q, r) != orient2d(p, q, r):
            found.append((p, q, r))
            if len(found) == count:
                break
    return found


def _float_sign(p: Point, q: Point, r: Point) -> int:
    """The sign of the determinant in plain floats, pivot p: what a naive answer says."""
    dqx, dqy, drx, dry = q[0] - p[0], q[1] - p[1], r[0] - p[0], r[1] - p[1]
    det = dqx * dry - dqy * drx
    return int(np.sign(det))


#: exact signs: no tolerance anywhere
TRIPLES: dict[str, Dataset[list[Triple]]] = {
    "integer-turns": Dataset(_integer_turns),
    "float-collinear": Dataset(_float_collinear,
                               hint="Compare the exact determinant with 0: a tolerance calls "
                                    "points that turn by a hair collinear."),
    "kettner-ulp": Dataset(_kettner_ulp, points=2, hint=NEAR_COLLINEAR_HINT),
    "scaled-triangles": Dataset(_scaled_triangles,
                                hint="Tiny or huge coordinates: compare the exact determinant "
                                     "with 0, not with a tolerance, and avoid float "
                                     "overflow/underflow."),
    "unseen-near-collinear": Dataset(_unseen_near_collinear, points=2, hint=NEAR_COLLINEAR_HINT),
}

#: (permutation of (p, q, r), sign factor): cycling keeps the turn, swapping flips it
PERMUTATIONS = [((0, 1, 2), 1), ((1, 2, 0), 1), ((2, 0, 1), 1),
                ((1, 0, 2), -1), ((0, 2, 1), -1), ((2, 1, 0), -1)]


@over_datasets(TRIPLES)
def test_orientation(student: Student, rng: np.random.Generator, name: str) -> None:
    dataset = TRIPLES[name]
    triples = dataset.build(rng)
    for (p, q, r), got in zip(triples, student.map("orientation", triples)):
        feedback.judge_turn(got, p, q, r, orient2d(p, q, r), hint=dataset.hint)


@pytest.mark.points(1)
def test_orientation_symmetry(student: Student, rng: np.random.Generator) -> None:
    calls = []  # (arguments, expected sign)
    for triple in _unseen_near_collinear(rng, count=3):
        sign = orient2d(*triple)
        for order, factor in PERMUTATIONS:
            calls.append(([np.array(triple[k]) for k in order], sign * factor))  # numpy points
    answers = student.map("orientation", [args for args, _ in calls])
    for (args, expected), got in zip(calls, answers):
        feedback.judge_turn(
            got, *args, expected,
            hint="These are the same three points in another order: cycling them keeps "
                 "the turn and swapping two reverses it. " + NEAR_COLLINEAR_HINT)


# ---------------------------------------------------------------------------
# convex hull point sets
# ---------------------------------------------------------------------------

def _random_300(rng: np.random.Generator) -> np.ndarray:
    return np.random.default_rng(300).uniform(-2.0, 3.0, size=(300, 2))


def _kettner_near_collinear(rng: np.random.Generator) -> np.ndarray:
    """Pins a few ulps around the diagonal from (0.5, 0.5) to (24, 24), plus three pins
    above it: the lower-right side of the band runs along the nearly collinear pins.
    With seed 22 float-based marches (any pivot) miss corners."""
    g = np.random.default_rng(22)
    cluster = [(0.5 + i * U, 0.5 + j * U) for i, j in g.integers(0, 256, (40, 2))]
    mid = [(12 + a * 2.0**-49, 12 + b * 2.0**-49) for a, b in g.integers(-16, 17, (8, 2))]
    mid2 = [(17.3 + a * 2.0**-48, 17.3 + b * 2.0**-48) for a, b in g.integers(-16, 17, (8, 2))]
    end = [(24 + a * 2.0**-48, 24 + b * 2.0**-48) for a, b in g.integers(-16, 17, (8, 2))]
    above = [(4.0, 9.0), (15.0, 27.0), (1.0, 20.0)]
    return np.array(cluster + mid + mid2 + end + above)


def _grid_5x5(rng: np.random.Generator) -> np.ndarray:
    xy = np.array([(x, y) for x in range(5) for y in range(5)], dtype=float)
    return np.random.default_rng(55).permutation(xy) * 0.5 + [-1.0, 2.0]


def _duplicates(rng: np.random.Generator) -> np.ndarray:
    """A hexagon and interior pins, a third of them repeated; the smallest pin comes 3 times."""
    g = np.random.default_rng(7)
    angles = np.arange(6) * np.pi / 3
    corners = np.round(np.c_[np.cos(angles), np.sin(angles)] * 4, 3)
    inside = g.uniform(-2, 2, size=(14, 2))
    base = np.vstack([corners, inside])
    repeats = base[g.choice(len(base), size=7, replace=False)]
    smallest = base[np.lexsort((base[:, 1], base[:, 0]))[0]]
    return g.permutation(np.vstack([base, repeats, smallest, smallest]))


def _all_collinear(rng: np.random.Generator) -> np.ndarray:
    t = np.random.default_rng(11).permutation(np.r_[np.arange(20), 7, 7])
    return np.c_[0.75 + 1.5 * t, -1.0 + 3.5 * t]  # every value is a short dyadic: exact


def _single_point(rng: np.random.Generator) -> np.ndarray:
    return np.array([[0.3, -1.7]])


def _two_points(rng: np.random.Generator) -> np.ndarray:
    return np.array([[2.5, 1.0], [-1.0, 4.0]])


def _same_place(rng: np.random.Generator) -> np.ndarray:
    return np.full((6, 2), [2.0, -3.0])


def _square_with_interior(rng: np.random.Generator) -> np.ndarray:
    g = np.random.default_rng(4)
    corners = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
    return g.permutation(np.vstack([g.uniform(-0.9, 0.9, size=(40, 2)), corners]))


def _large_2000(rng: np.random.Generator) -> np.ndarray:
    return np.random.default_rng(2000).uniform(0.0, 1.0, size=(2000, 2))


def _unseen_circle(rng: np.random.Generator) -> np.ndarray:
    """Pins on a circle (every one a corner) around a cloud of interior pins."""
    m, k = int(rng.integers(40, 120)), int(rng.integers(20, 80))
    radius, centre = rng.uniform(0.5, 50.0), rng.uniform(-100.0, 100.0, 2)
    angles = 2 * np.pi * (np.arange(m) + 0.3 * rng.uniform(size=m)) / m
    ring = centre + radius * np.c_[np.cos(angles), np.sin(angles)]
    cloud = centre + 0.7 * radius * rng.uniform(-1.0, 1.0, size=(k, 2))
    return rng.permutation(np.vstack([ring, cloud]))


def _unseen_lattice(rng: np.random.Generator) -> np.ndarray:
    """Lattice pins in a sheared, cut rectangle: many pins on slanted and straight edges."""
    w, h = int(rng.integers(6, 14)), int(rng.integers(5, 12))
    cut, shear = int(rng.integers(2, min(w, h))), int(rng.integers(-2, 3))
    cells = [(x, y) for x in range(w + 1) for y in range(h + 1) if x + y <= w + h - cut]
    keep = [c for c in cells if rng.uniform() < 0.6 or 0 in c or c[0] == w or c[1] == h
            or c[0] + c[1] == w + h - cut]
    xy = np.array(keep, dtype=float)
    xy[:, 0] += shear * xy[:, 1]
    return rng.permutation(xy * 0.25 + rng.integers(-40, 40, 2) * 0.125)


def _unseen_clusters(rng: np.random.Generator) -> np.ndarray:
    """Gaussian clusters of very different sizes and spreads."""
    parts = [rng.uniform(-100, 100, 2) + 10.0 ** rng.uniform(-3, 1) * rng.standard_normal(
        (int(rng.integers(30, 200)), 2)) for _ in range(int(rng.integers(3, 7)))]
    return rng.permutation(np.vstack(parts))


def _unseen_tiny(rng: np.random.Generator) -> np.ndarray:
    """A cloud 1e-9 wide far from the origin: determinants of order 1e-18."""
    return rng.uniform(-1000.0, 1000.0, 2) + 1e-9 * rng.uniform(size=(150, 2))


#: exact hulls: no tolerance anywhere
DATASETS: dict[str, Dataset[np.ndarray]] = {
    "random-300": Dataset(_random_300, points=2),
    "kettner-near-collinear": Dataset(_kettner_near_collinear, points=2),
    "grid-5x5": Dataset(_grid_5x5, points=2),
    "duplicates": Dataset(_duplicates),
    "all-collinear": Dataset(_all_collinear),
    "single-point": Dataset(_single_point),
    "two-points": Dataset(_two_points),
    "same-place": Dataset(_same_place),
    "square-with-interior": Dataset(_square_with_interior),
    "large-2000": Dataset(_large_2000, points=2),
    "unseen-circle": Dataset(_unseen_circle),
    "unseen-lattice": Dataset(_unseen_lattice, points=2),
    "unseen-clusters": Dataset(_unseen_clusters),
    "unseen-tiny": Dataset(_unseen_tiny),
}
#: well conditioned: scipy must find the same hull
SCIPY_UNIQUE = {"random-300", "grid-5x5", "duplicates", "square-with-interior", "large-2000"}
#: a stub can answer these: earned only with a general hull
DEGENERATE = {"all-collinear", "single-point", "two-points", "same-place"}


def boundary_walk(points: np.ndarray, hull: list[int]) -> list[int]:
    """Every distinct pin on the hull's boundary, counter-clockwise from ``hull[0]``.

    For a degenerate hull (two corners) the pins on the segment, in order from
    the first corner to the second.
    """
    canon = feedback.canonical_indices(points)
    hull = [int(canon[v]) for v in hull]
    distinct = np.unique(canon)
    if len(hull) == 1:
        return hull
    edges = list(zip(hull, hull[1:] + hull[:1])) if len(hull) > 2 else [(hull[0], hull[1])]
    walk: list[int] = []
    for a, b in edges:
        pa, pb = points[a], points[b]
        lo, hi = np.minimum(pa, pb), np.maximum(pa, pb)
        in_box = distinct[np.all((points[distinct] >= lo) & (points[distinct] <= hi), axis=1)]
        inner = [int(i) for i in in_box
                 if i not in (a, b) and orient2d(pa, pb, points[i]) == 0]
        # along a segment the lexicographic order of the pins is their order on it
        inner.sort(key=lambda i: (float(points[i][0]), float(points[i][1])),
                   reverse=(float(pb[0]), float(pb[1])) < (float(pa[0]), float(pa[1])))
        walk += [a] + inner
    return walk + ([hull[1]] if len(hull) == 2 else [])


def oracle(points: np.ndarray, *, scipy_unique: bool) -> tuple[list[int], list[int]]:
    """The expected hull (canonical indices) and its boundary walk."""
    canon = feedback.canonical_indices(points)
    hull = [int(canon[v]) for v in reference_hull(points)]
    if scipy_unique:
        theirs = [int(canon[v]) for v in ConvexHull(points).vertices]
        if not same_cycle(theirs, hull):
            raise RuntimeError("reference.convex_hull and scipy.spatial.ConvexHull "
                               "disagree on a well-conditioned dataset: fix the oracle.")
    return hull, boundary_walk(points, hull)


@over_datasets(DATASETS)
def test_convex_hull(student: Student, credit: Credit, rng: np.random.Generator,
                     name: str) -> None:
    points = DATASETS[name].build(rng)
    expected, boundary = oracle(points, scipy_unique=name in SCIPY_UNIQUE)
    if name in DEGENERATE:
        feedback.require_general_case(student.convex_hull, f"{name} case")
    got = student.convex_hull(points)
    feedback.grade_hull(got, points, expected, boundary, credit)


@pytest.mark.points(2)
@pytest.mark.visibility("input")  # the student sees which board, never the expected hull
def test_convex_hull_your_pins(student: Student, credit: Credit, variant: VariantView,
                               feedback: Feedback) -> None:
    points = np.array(variant["pins"], dtype=float)
    feedback.input(f"convex_hull(pins) with the {len(points)} pins of your notebook's "
                   "parameters cell (your own board)")
    expected, boundary = oracle(points, scipy_unique=True)
    got = student.convex_hull(points)
    variant.record("pins_hull", got)
    hull_feedback.grade_hull(got, points, expected, boundary, credit)
