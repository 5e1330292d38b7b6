"""Staged feedback on in-circle, triangulation and mesh-plot answers (public and hidden checks).

A triangulation check reads the answer with :func:`as_triangles` (type and
shape), then hands the index array to a *judge*: a function that returns when
the triangles are right, noting the conventions they break (clockwise
triangles) in a :class:`~autograder.checks.Broken` record, or raises
``CheckFailure`` saying what is wrong.
:func:`grade_triangulation` runs the judge and, when it fails, tries the same
answer shifted down by one: a triangulation that is right with 1-based
indices earns part of the points.

The judge in this file, :func:`known_answer_judge`, compares with answers
listed in advance (every valid triangulation of a small or stored point
set): bookkeeping on index triples only. The hidden checks bring an exact
geometric judge that reuses the messages below.

Shape of the feedback: type, then indices, then which triangles, then their
orientation.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from matplotlib.path import Path
from numpy.typing import ArrayLike

from autograder.checks import (
    Broken,
    CheckFailure,
    Conventions,
    Credit,
    Feedback,
    FigureData,
    Student,
    call_for_figure,
    describe,
    expect_array,
    expect_figure,
    expect_indices,
    sentence,
    show_number,
    show_point,
)

#: what a right answer keeps of the points for each convention it breaks (multiplied together)
CONVENTIONS = Conventions({
    "clockwise": 0.5,   # right triangles, some listed clockwise
    "one-based": 0.5,   # right triangles, indices counted from 1
    "not-bool": 0.5,    # right answers as 1/0 instead of True/False
    "no-return": 0.5,   # right plot, but the figure was not returned
})

NAME = "delaunay(points)"
SUPER_HINT = "a super-triangle that is too small?"

#: judge(triangles, broken): returns when right (noting broken conventions), else CheckFailure
Judge = Callable[[np.ndarray, Broken], None]

#: a triangle's three indices, written like a point: (4, 0, 7)
show_triangle = show_point


def count_message(expected: int, n: int, hull: int, got: int) -> str:
    """``expected 94 triangles for 50 points with 4 on the hull, got 90``."""
    return (f"expected {expected} triangles for {n} points with {hull} on the hull "
            f"(2n - 2 - h), got {got}")


# ---------------------------------------------------------------------------
# reading a triangulation
# ---------------------------------------------------------------------------

def as_triangles(got: object) -> np.ndarray:
    """The answer as an ``(m, 3)`` int64 array with ``m >= 1``, or CheckFailure."""
    hint = ("Return an (m, 3) array of integer indices into `points`, one row per "
            "triangle, e.g. np.array(triangles, dtype=int).")
    if isinstance(got, (list, tuple, np.ndarray)) and np.size(got) == 0:
        raise CheckFailure(
            f"{NAME} returned {describe(got)} with no triangles in it: the answer is well "
            "formed but empty, and every set of 3 or more points not all on one line has "
            "triangles (2n - 2 - h of them). Check that your loop keeps the triangles it "
            "builds: for example, that removing the triangles that touch the super-triangle "
            "does not remove them all.")
    arr = expect_array(got, shape=(None, 3), dtype_kind="iu", name=NAME, hint=hint)
    return arr.astype(np.int64)


def check_indices(tri: np.ndarray, n: int) -> None:
    """Fail on indices outside ``0..n-1``, a vertex repeated in a triangle, a triangle twice."""
    super_corner = bool(np.any((tri >= n) & (tri <= n + 2)))
    expect_indices(tri, n, name=NAME, at=lambda i: f"triangle {i[0]} {show_triangle(tri[i[0]])}",
                   hint="Is it a corner of the super-triangle? Remove every triangle that touches "
                        "one of its corners before returning." if super_corner else "")
    same = np.flatnonzero((tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2])
                          | (tri[:, 0] == tri[:, 2]))
    if same.size:
        k = int(same[0])
        raise CheckFailure(f"Triangle {k} {show_triangle(tri[k])} repeats a vertex; a "
                           "triangle has three different corners.")
    seen: dict[tuple[int, ...], int] = {}
    for k, t in enumerate(np.sort(tri, axis=1).tolist()):
        first = seen.setdefault(tuple(t), k)
        if first != k:
            raise CheckFailure(f"Triangles {first} {show_triangle(tri[first])} and {k} "
                               f"{show_triangle(tri[k])} are the same triangle; list each "
                               "triangle once.")


def clockwise_note(tri: np.ndarray, clockwise: Sequence[int]) -> str:
    k = int(clockwise[0])
    if len(tri) == 1:
        scope = ""
    elif len(clockwise) == len(tri):
        scope = f" (all {len(tri)} triangles are clockwise)"
    elif len(clockwise) > 1:
        scope = f" ({len(clockwise)} of {len(tri)} triangles are clockwise)"
    else:
        scope = " (the only one)"
    return (f"triangle {k} {show_triangle(tri[k])} is clockwise{scope}: list the vertices "
            "of every triangle counter-clockwise")


def grade_triangulation(got: object, n: int, judge: Judge, credit: Credit) -> None:
    """Judge the answer and end the check: pass, ``credit.partial(...)``, or CheckFailure."""
    tri = as_triangles(got)
    broken = CONVENTIONS.record()
    try:
        judge(tri, broken)
    except CheckFailure as first:
        if tri.min() < 1 or tri.max() > n:
            raise
        broken = CONVENTIONS.record()
        broken.note("one-based", f"indices must start at 0: your triangles are right with "
                                 f"every index counted from 1 (you use 1 to {int(tri.max())} "
                                 f"for {n} points), so subtract 1")
        try:
            judge(tri - 1, broken)
        except CheckFailure as second:
            if tri.max() < n:
                raise first from None
            raise CheckFailure(f"Indices must start at 0 (you use 1 to {n} for {n} points). "
                               f"Even counted from 1 your triangles are not right: {second}"
                               ) from None
    broken.finish(credit)


# ---------------------------------------------------------------------------
# judging against answers known in advance
# ---------------------------------------------------------------------------

def boundary_edges(tri: np.ndarray) -> list[tuple[int, int]]:
    """Directed edges of counter-clockwise triangles whose reverse is in no triangle."""
    edges = {(int(t[i]), int(t[(i + 1) % 3])) for t in tri for i in range(3)}
    return sorted(e for e in edges if (e[1], e[0]) not in edges)


def _float_inside(points: np.ndarray, t: Sequence[int]) -> int | None:
    """A point clearly (float, with a wide margin) inside the circumcircle of ``t``; a hint only."""
    a, b, c = (points[int(v)] for v in t)
    d = points - a
    rows = np.array([b - a, c - a])
    lift = (rows ** 2).sum(axis=1)
    det2 = rows[0, 0] * rows[1, 1] - rows[0, 1] * rows[1, 0]
    if det2 == 0:
        return None
    centre = np.array([lift[0] * rows[1, 1] - lift[1] * rows[0, 1],
                       lift[1] * rows[0, 0] - lift[0] * rows[1, 0]]) / (2 * det2)
    r2 = (centre ** 2).sum()
    dist2 = ((d - centre) ** 2).sum(axis=1)
    inside = np.flatnonzero(dist2 < r2 * (1 - 1e-6))
    inside = [int(i) for i in inside if i not in {int(v) for v in t}]
    return inside[0] if inside else None


def known_answer_judge(points: ArrayLike, answers: Sequence[ArrayLike]) -> Judge:
    """A judge that accepts exactly the triangulations in ``answers`` (ccw index triples)."""
    pts = np.asarray(points, dtype=float)
    n = len(pts)
    options = [np.asarray(a, dtype=np.int64).reshape(-1, 3) for a in answers]

    def judge(tri: np.ndarray, broken: Broken) -> None:
        check_indices(tri, n)
        got = [tuple(sorted(t)) for t in tri.tolist()]
        best = max(options, key=lambda a: len(set(got) & {tuple(sorted(t))
                                                         for t in a.tolist()}))
        ccw = {tuple(sorted(t)): tuple(t) for t in best.tolist()}
        missing = [t for t in best.tolist() if tuple(sorted(t)) not in set(got)]
        extra = [k for k, t in enumerate(got) if t not in ccw]
        if missing or extra:
            raise CheckFailure(_difference(pts, tri, best, missing, extra))
        clockwise = [k for k, t in enumerate(tri.tolist())
                     if not _same_rotation(t, ccw[tuple(sorted(t))])]
        if clockwise:
            broken.note("clockwise", clockwise_note(tri, clockwise))

    return judge


def _same_rotation(t: Sequence[int], ccw: Sequence[int]) -> bool:
    c = tuple(ccw)
    return tuple(t) in {c, c[1:] + c[:1], c[2:] + c[:2]}


def _difference(pts: np.ndarray, tri: np.ndarray, best: np.ndarray,
                missing: list[list[int]], extra: list[int]) -> str:
    n, m, expected = len(pts), len(tri), len(best)
    hull = boundary_edges(best)
    count = count_message(expected, n, len(hull), m) if m != expected else ""
    if extra:
        k = extra[0]
        q = _float_inside(pts, tri[k])
        why = (f"point {q} at {show_point(pts[q])} lies strictly inside the circumcircle of "
               f"triangle {k} {show_triangle(tri[k])}, so that triangle is not Delaunay"
               if q is not None else
               f"triangle {k} {show_triangle(tri[k])} is not a triangle of the Delaunay "
               "triangulation")
        return sentence(f"{count}: {why}" if count else why)
    hull_set = set(hull)
    along = [t for t in missing
             if any((t[i], t[(i + 1) % 3]) in hull_set for i in range(3))]
    if along:
        why = (f"the triangles along the hull are missing ({SUPER_HINT}); for example "
               f"{show_triangle(along[0])} is missing")
    else:
        why = f"triangle {show_triangle(missing[0])} is missing"
    return sentence(f"{count}: {why}" if count else why)


# ---------------------------------------------------------------------------
# in_circle answers
# ---------------------------------------------------------------------------

def in_circle_call(a: ArrayLike, b: ArrayLike, c: ArrayLike, d: ArrayLike) -> str:
    return f"in_circle({show_point(a)}, {show_point(b)}, {show_point(c)}, {show_point(d)})"


WHERE = {1: "strictly inside", 0: "exactly on", -1: "outside"}
SIGN_HINT = ("Check the sign convention: for counter-clockwise a, b, c the in-circle "
             "determinant is positive exactly when d is inside the circle.")


def judge_in_circle(cases: Sequence[tuple[tuple[ArrayLike, ...], object, int]], *,
                    hint: str = "", credit: Credit) -> None:
    """Judge ``(args, got, where)`` triples; ``where`` is +1 inside, 0 on, -1 outside.

    Ends the check: pass, partial credit (answers right but not ``bool``), or
    CheckFailure with the first wrong case.
    """
    wrong: list[tuple[str, bool, int]] = []
    not_bool: list[tuple[str, object]] = []
    for args, got, where in cases:
        call = in_circle_call(*args)
        if isinstance(got, bool):
            value = got
        elif isinstance(got, (int, float)) and got in (0, 1):
            value = bool(got)
            not_bool.append((call, got))
        else:
            raise CheckFailure(f"{call} returned {describe(got)}; return True or False "
                               "(for example `return det > 0`).")
        if value != (where > 0):
            wrong.append((call, value, where))
    if wrong:
        call, value, where = wrong[0]
        more = f" ({len(wrong)} of {len(cases)} cases are wrong)" if len(wrong) > 1 else ""
        message = (f"{call} returned {value}; expected {where > 0}: d lies {WHERE[where]} "
                   f"the circle through a, b and c{more}.")
        decided = [w for _, _, w in wrong if w != 0]
        all_flipped = decided and len(decided) == sum(1 for *_, w in cases if w != 0)
        if where == 0:
            message += " Strictly inside means that a point on the circle gives False."
        if all_flipped:
            message += " " + SIGN_HINT
        elif hint:
            message += " " + hint
        raise CheckFailure(message)
    if not_bool:
        call, got = not_bool[0]
        CONVENTIONS.partial(credit, "not-bool",
                            f"{call} returned {got!r} ({type(got).__name__}); the answers are "
                            "right, but return True or False (a bool), for example "
                            "`return det > 0`.")


# ---------------------------------------------------------------------------
# a function plotted on the mesh (figure data)
# ---------------------------------------------------------------------------

#: how far the colour range may be from the range of u, as a fraction of that range:
#: filled contours colour each band by its middle value, and flat tripcolor colours a
#: triangle by the mean of its corners, so neither reaches min(u) or max(u) exactly
COLOUR_RANGE_TOL = 0.25
#: share of sample points (triangle centroids) the filled area must cover
COVERAGE = 0.95
MAX_SAMPLES = 400


def _covered(segments: Sequence[ArrayLike], samples: np.ndarray) -> np.ndarray:
    """Even-odd rule over every closed sub-path: True where a sample is inside the region."""
    inside = np.zeros(len(samples), dtype=bool)
    for seg in segments:
        poly = np.asarray(seg, dtype=float).reshape(-1, 2)
        if len(poly) >= 3 and np.all(np.isfinite(poly)):
            inside ^= Path(poly).contains_points(samples)
    return inside


def judge_figure(figure: object, points: ArrayLike, triangles: ArrayLike, u: ArrayLike) -> None:
    """Fail unless some collection fills the mesh and is coloured over the range of ``u``."""
    pts = np.asarray(points, dtype=float)
    tri = np.asarray(triangles, dtype=np.int64)
    u = np.asarray(u, dtype=float)
    fig = expect_figure(figure, name="plot_on_mesh(points, triangles, u)")
    step = max(1, len(tri) // MAX_SAMPLES)
    samples = pts[tri[::step]].mean(axis=1)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    slack = 0.01 * float(np.max(hi - lo))
    best_share, misplaced = 0.0, 0
    coloured: list[FigureData] = []
    for ax in fig["axes"]:
        for coll in ax.get("collections", []):
            segments = [s for s in coll.get("segments", []) if len(s)]
            if not segments:
                continue
            vertices = np.vstack([np.asarray(s, dtype=float).reshape(-1, 2) for s in segments])
            vertices = vertices[np.all(np.isfinite(vertices), axis=1)]
            if len(vertices) == 0:
                continue
            if (np.any(vertices.min(axis=0) < lo - slack)
                    or np.any(vertices.max(axis=0) > hi + slack)):
                misplaced += 1
                continue
            share = float(_covered(segments, samples).mean())
            best_share = max(best_share, share)
            if share >= COVERAGE:
                coloured.append(coll)
    if not coloured:
        if best_share:
            found = f"the best filled area covers only {best_share:.0%} of the triangles"
        elif misplaced:
            found = (f"what it fills reaches outside the points, which lie in x from "
                     f"{show_number(lo[0], 6)} to {show_number(hi[0], 6)} and y from "
                     f"{show_number(lo[1], 6)} to {show_number(hi[1], 6)} "
                     "(x and y swapped?)")
        else:
            found = "it has no filled area"
        raise CheckFailure(
            f"Your figure does not fill the mesh: {found}. Fill the triangles with colours "
            "of u, e.g. ax.tricontourf(x, y, triangles, u, 20) or ax.tripcolor(x, y, "
            "triangles, u), where x and y are the columns of `points`.")
    _check_colours(coloured, u)


def _check_colours(coloured: list[FigureData], u: np.ndarray) -> None:
    umin, umax = float(u.min()), float(u.max())
    tol = COLOUR_RANGE_TOL * (umax - umin) + 1e-12 * max(abs(umin), abs(umax), 1.0)
    ranges = []
    for coll in coloured:
        values = coll.get("array")
        if values is None:
            continue
        values = np.asarray(values, dtype=float).ravel()
        values = values[np.isfinite(values)]
        if values.size == 0:
            continue
        cmin, cmax = float(values.min()), float(values.max())
        if abs(cmin - umin) <= tol and abs(cmax - umax) <= tol:
            return
        ranges.append((cmin, cmax))
    if not ranges:
        raise CheckFailure("The filled area of your figure has no colour data: colour the "
                           "triangles by u (tricontourf or tripcolor with u as the values).")
    cmin, cmax = ranges[0]
    raise CheckFailure(f"The colours of your plot run from {show_number(cmin, 6)} to "
                       f"{show_number(cmax, 6)}, but u runs from {show_number(umin, 6)} to "
                       f"{show_number(umax, 6)}: colour the mesh by the values u "
                       "themselves, one value per point.")


def grade_figure(student: Student, points: np.ndarray, triangles: np.ndarray, u: np.ndarray,
                 credit: Credit, feedback: Feedback) -> None:
    """Call ``plot_on_mesh``, attach its picture, and judge it (figure returned or left open)."""
    value, figure = call_for_figure(student, "plot_on_mesh", points, triangles, u,
                                    feedback=feedback, label="your plot_on_mesh")
    if value is None and figure is not None:
        judge_figure(figure, points, triangles, u)
        CONVENTIONS.partial(credit, "no-return",
                            "Your plot is right, but plot_on_mesh returned None: end it with "
                            "`return fig` so that the figure can be used (and graded).")
    judge_figure(value, points, triangles, u)
