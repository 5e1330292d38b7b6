"""Exact in-circle predicate and Delaunay triangulations in the plane.

The in-circle test is evaluated like :func:`reference.orient2d`: a
floating-point filter with Shewchuk's certified error bound, and an exact
recomputation with :class:`fractions.Fraction` when the filter cannot decide.
:func:`delaunay` is the Bowyer-Watson algorithm with ghost triangles (no
super-triangle whose vertices could end up inside a circumcircle), and
:func:`is_delaunay` checks a triangulation with the same exact predicates.

Integers too large to be doubles (beyond ``2**53``) are computed with exactly.

Public functions: :func:`incircle`, :func:`incircle_many`, :func:`delaunay`,
:func:`is_delaunay`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from reference import _predicates as P
from reference._validation import as_exact_array, as_exact_point, as_exact_points

__all__ = ["incircle", "incircle_many", "delaunay", "is_delaunay"]

# Seed of the insertion order: the triangulation is a deterministic function
# of the input.
_SEED = 20240607


# ---------------------------------------------------------------------------
# In-circle predicate
# ---------------------------------------------------------------------------


def _collinear_error(rows: str) -> ValueError:
    return ValueError(
        f"`a`, `b` and `c` must not be collinear (they define no circle); got {rows}."
    )


def incircle_many(a: ArrayLike, b: ArrayLike, c: ArrayLike, d: ArrayLike) -> NDArray[np.int8]:
    r"""Exact in-circle test for many quadruples of points at once.

    Parameters
    ----------
    a, b, c : array_like, shape (..., 2)
        Corners of the circles, in either orientation, never collinear.
    d : array_like, shape (..., 2)
        Query points. The four shapes must broadcast together.

    Returns
    -------
    ndarray of int8, shape (m,)
        ``incircle(a[i], b[i], c[i], d[i])`` for each row ``i`` of the
        broadcast arrays, flattened to one dimension: ``+1`` inside, ``0`` on
        the circle, ``-1`` outside.

    Raises
    ------
    ValueError
        If a row's ``a, b, c`` are collinear (the first such row is named), an
        argument holds NaN, infinity, a number too large for a double or
        non-numbers, is complex or a masked array, or the shapes do not
        broadcast to ``(..., 2)``.

    Notes
    -----
    The floating-point filter of :func:`incircle` is applied to all rows at
    once and only the rows it cannot decide are recomputed exactly; integer
    input beyond ``2**53`` is computed exactly throughout. The orientation of
    each ``a, b, c`` is computed with :func:`reference.orient2d_many` and
    multiplies the determinant, so the answer does not depend on it.

    See Also
    --------
    incircle : the same predicate for one quadruple.

    References
    ----------
    .. [1] J. R. Shewchuk, "Adaptive precision floating-point arithmetic and
       fast robust geometric predicates", Discrete & Computational Geometry
       18, 305-363 (1997). :doi:`10.1007/PL00009321`

    Examples
    --------
    >>> from reference import incircle_many
    >>> incircle_many([1, 0], [0, 1], [-1, 0], [[0, 0], [0, -1], [2, 2]])
    array([ 1,  0, -1], dtype=int8)
    """
    arrays = [as_exact_array(v, name) for v, name in zip((a, b, c, d), "abcd")]
    for v, name in zip(arrays, "abcd"):
        if v.ndim == 0 or v.shape[-1] != 2:
            raise ValueError(
                f"`{name}` must hold points, an array of shape (..., 2); got {v.shape}."
            )
    try:
        shape = np.broadcast_shapes(*(v.shape for v in arrays))
    except ValueError:
        shapes = ", ".join(str(v.shape) for v in arrays)
        raise ValueError(
            f"`a`, `b`, `c` and `d` must have shapes that broadcast together; got {shapes}."
        ) from None
    full = [np.broadcast_to(v, shape).reshape(-1, 2) for v in arrays]
    turn = P.orient_many(*full[:3])
    flat = np.flatnonzero(turn == 0)
    if flat.size:
        i = int(flat[0])
        raise _collinear_error(
            f"row {i}: a={full[0][i].tolist()}, b={full[1][i].tolist()}, c={full[2][i].tolist()}"
        )
    return (turn * P.incircle_many_ccw(*full)).astype(np.int8)


def incircle(a: ArrayLike, b: ArrayLike, c: ArrayLike, d: ArrayLike) -> int:
    r"""Exact position of a point relative to the circle through three points.

    Parameters
    ----------
    a, b, c : array_like, shape (2,)
        Finite points, not collinear, in either orientation.
    d : array_like, shape (2,)
        Finite query point.

    Returns
    -------
    int
        ``+1`` when ``d`` lies strictly inside the circle through ``a, b, c``,
        ``0`` when it lies on the circle and ``-1`` when it lies outside. The
        answer does not depend on the order of ``a, b, c`` and is exact for
        every finite double input.

    Raises
    ------
    ValueError
        If a point does not have shape ``(2,)`` or is not finite, or
        if ``a, b, c`` are collinear (they define no circle).

    Notes
    -----
    For counter-clockwise ``a, b, c`` the point ``d`` is inside the circle
    exactly when

    .. math::

        \det\begin{pmatrix}
        a_x - d_x & a_y - d_y & (a_x - d_x)^2 + (a_y - d_y)^2 \\
        b_x - d_x & b_y - d_y & (b_x - d_x)^2 + (b_y - d_y)^2 \\
        c_x - d_x & c_y - d_y & (c_x - d_x)^2 + (c_y - d_y)^2
        \end{pmatrix} > 0

    (the lifting map :math:`(x, y) \mapsto (x, y, x^2 + y^2)` turns circles
    into planes). Swapping two of ``a, b, c`` flips the sign, so the
    determinant is multiplied by ``orient2d(a, b, c)`` to make the answer
    independent of the orientation.

    The determinant is computed in floating point first; its rounding error is
    at most ``(10 + 96 eps) eps P`` where ``P`` is the permanent (the same
    expansion with absolute values) and ``eps = 2**-53`` (Shewchuk 1997,
    Section 4.3). When the computed value does not exceed that bound, or when
    a coordinate difference is so small (below ``2**-200``) or large (above
    ``2**250``) that a product could underflow or overflow, the sign is
    recomputed exactly with :class:`fractions.Fraction`.

    References
    ----------
    .. [1] J. R. Shewchuk, "Adaptive precision floating-point arithmetic and
       fast robust geometric predicates", Discrete & Computational Geometry
       18, 305-363 (1997). :doi:`10.1007/PL00009321`
    .. [2] L. Kettner, K. Mehlhorn, S. Pion, S. Schirra and C. Yap, "Classroom
       examples of robustness problems in geometric computations",
       Computational Geometry 40(1), 61-78 (2008).
       :doi:`10.1016/j.comgeo.2007.06.003`

    Examples
    --------
    >>> from reference import incircle
    >>> incircle([1, 0], [0, 1], [-1, 0], [0, 0])
    1
    >>> incircle([1, 0], [0, 1], [-1, 0], [0, -1])
    0
    >>> incircle([1, 0], [-1, 0], [0, 1], [2, 2])  # clockwise a, b, c
    -1

    A point one unit in the last place inside the unit circle:

    >>> incircle([1, 0], [0, 1], [-1, 0], [0, -1 + 2.0**-53])
    1
    """
    pts = [as_exact_point(v, name) for v, name in zip((a, b, c, d), "abcd")]
    if P.is_exact_objects(*pts):
        xy = [v for p in pts for v in P.to_objects(p).tolist()]
        orient, inside = P.orient_num, P.incircle_num
    else:
        xy = [float(v) for p in pts for v in p]
        orient, inside = P.orient_xy, P.incircle_xy
    orientation = orient(*xy[:6])
    if orientation == 0:
        raise _collinear_error(f"a={xy[0:2]}, b={xy[2:4]}, c={xy[4:6]}")
    return orientation * inside(*xy)


# ---------------------------------------------------------------------------
# Bowyer-Watson with ghost triangles
# ---------------------------------------------------------------------------


def _hilbert_keys(xy: NDArray[np.float64], bits: int = 16) -> NDArray[np.int64]:
    """Index of each point along a Hilbert curve over its bounding box."""
    half = 0.5 * xy  # halving keeps the differences below from overflowing
    lo = half.min(axis=0)
    span = half.max(axis=0) - lo
    span[span == 0] = 1.0
    side = 1 << bits
    q = np.clip(((half - lo) / span * (side - 1)).astype(np.int64), 0, side - 1)
    x, y = q[:, 0].copy(), q[:, 1].copy()
    d = np.zeros(xy.shape[0], dtype=np.int64)
    s = side >> 1
    while s > 0:
        rx = (x & s) > 0
        ry = (y & s) > 0
        d += s * s * ((3 * rx) ^ ry)
        # rotate the quadrant so that the curve is continuous
        flip = ~ry & rx
        x = np.where(flip, side - 1 - x, x)
        y = np.where(flip, side - 1 - y, y)
        swap = ~ry
        x, y = np.where(swap, y, x), np.where(swap, x, y)
        s >>= 1
    return d


def _brio_order(xy: NDArray[np.float64]) -> NDArray[np.intp]:
    """Biased randomised insertion order (Amenta, Choi and Rote 2003).

    A seeded random permutation split into rounds of doubling size; each
    round is sorted along a Hilbert curve, so consecutive points are close and
    the walk from the previous insertion is short, while the rounds keep the
    expected cost of a random order.
    """
    n = xy.shape[0]
    perm = np.random.default_rng(_SEED).permutation(n)
    keys = _hilbert_keys(xy)
    ends = [n]
    while ends[-1] > 64:
        ends.append(ends[-1] // 2)
    bounds = [0] + ends[::-1]
    rounds = [perm[lo:hi][np.argsort(keys[perm[lo:hi]], kind="stable")]
              for lo, hi in zip(bounds[:-1], bounds[1:])]  # fmt: skip
    return np.concatenate(rounds)


class _Triangulation:
    """Mutable triangle mesh used while :func:`delaunay` runs (never returned).

    Triangle ``t`` has vertices ``tv[t]`` (counter-clockwise) and neighbours
    ``tn[t]``, where ``tn[t][i]`` is across the edge opposite ``tv[t][i]``.
    The ghost vertex ``g`` (an index past the last point) stands for the point
    at infinity: a ghost triangle ``(x, y, g)`` sits outside the hull edge
    ``y -> x``, and its "circumcircle" is the open half-plane to the left of
    ``x -> y`` together with the open segment ``xy`` (Shewchuk's convention),
    so points outside the hull are inserted like any other point.
    """

    def __init__(self, xs: list[Any], ys: list[Any], mode: str) -> None:
        self.xs, self.ys = xs, ys
        self.g = len(xs)
        self.orient, self.incircle = _PREDICATES[mode]
        self.tv: list[tuple[int, int, int]] = []
        self.tn: list[list[int]] = []
        self.alive: list[bool] = []
        self.free: list[int] = []
        self.last = 0  # a live real triangle where the next walk starts

    # -- construction -----------------------------------------------------

    def start(self, a: int, b: int, c: int) -> None:
        """First counter-clockwise triangle ``a b c`` and its three ghosts."""
        g = self.g
        tris = [(a, b, c), (b, a, g), (c, b, g), (a, c, g)]
        edges = {}
        for t, (u, v, w) in enumerate(tris):
            edges[u, v], edges[v, w], edges[w, u] = (t, 2), (t, 0), (t, 1)
        self.tv = tris
        self.tn = [[0, 0, 0] for _ in tris]
        for (u, v), (t, i) in edges.items():
            self.tn[t][i] = edges[v, u][0]
        self.alive = [True] * 4

    def _new(self, verts: tuple[int, int, int]) -> int:
        if self.free:
            t = self.free.pop()
            self.tv[t] = verts
            self.alive[t] = True
            return t
        self.tv.append(verts)
        self.tn.append([0, 0, 0])
        self.alive.append(True)
        return len(self.tv) - 1

    # -- predicates -------------------------------------------------------

    def conflicts(self, t: int, p: int) -> bool:
        """True when point ``p`` lies in the (open) circumcircle of ``t``."""
        xs, ys = self.xs, self.ys
        a, b, c = self.tv[t]
        if c == self.g:
            o = self.orient(xs[a], ys[a], xs[b], ys[b], xs[p], ys[p])
            if o != 0:
                return o > 0
            # collinear with the hull edge: inside the open segment?
            if xs[a] != xs[b]:
                return min(xs[a], xs[b]) < xs[p] < max(xs[a], xs[b])
            return min(ys[a], ys[b]) < ys[p] < max(ys[a], ys[b])
        return self.incircle(xs[a], ys[a], xs[b], ys[b], xs[c], ys[c], xs[p], ys[p]) > 0

    # -- insertion --------------------------------------------------------

    def locate(self, p: int) -> int:
        """A triangle whose circumcircle contains ``p``, by a visibility walk.

        From ``self.last``, cross any edge that has ``p`` strictly on its
        outer side until none does (``p`` is in the closed triangle, hence in
        its open circumcircle since ``p`` is not a vertex) or a ghost triangle
        is entered (``p`` is strictly outside that hull edge). The first edge
        tried rotates from step to step, which prevents cycles; a step budget
        guards the loop and falls back to a scan of all triangles.
        """
        xs, ys, tv, tn, g, orient = self.xs, self.ys, self.tv, self.tn, self.g, self.orient
        px, py = xs[p], ys[p]
        t, came = self.last, -1
        for step in range(4 * len(tv) + 16):
            verts = tv[t]
            if verts[2] == g:
                return t
            for k in range(3):
                i = (step + k) % 3
                nb = tn[t][i]
                if nb == came:
                    continue
                u, v = verts[(i + 1) % 3], verts[(i + 2) % 3]
                if orient(xs[u], ys[u], xs[v], ys[v], px, py) < 0:
                    t, came = nb, t
                    break
            else:
                return t
        return next(  # pragma: no cover - the walk ends on Delaunay meshes
            t for t in range(len(tv)) if self.alive[t] and self.conflicts(t, p)
        )

    def insert(self, p: int) -> None:
        """Bowyer-Watson step: remove the triangles in conflict with ``p`` and
        connect ``p`` to the boundary of the cavity."""
        tv, tn = self.tv, self.tn
        first = self.locate(p)
        cavity = [first]
        status = {first: True}
        boundary = []  # (x, y, outside triangle)
        for t in cavity:  # grows while iterating: a breadth-first search
            verts = tv[t]
            for i in range(3):
                nb = tn[t][i]
                inside = status.get(nb)
                if inside is None:
                    inside = status[nb] = self.conflicts(nb, p)
                    if inside:
                        cavity.append(nb)
                if not inside:
                    boundary.append((verts[(i + 1) % 3], verts[(i + 2) % 3], nb))
        for t in cavity:
            self.alive[t] = False
            self.free.append(t)
        self._fill(p, boundary)

    def _fill(self, p: int, boundary: list[tuple[int, int, int]]) -> None:
        """New triangles ``(x, y, p)`` on the cavity's boundary edges ``x -> y``."""
        tv, tn, g = self.tv, self.tn, self.g
        by_start, by_end, made = {}, {}, []
        for x, y, out in boundary:
            t = self._new((x, y, p))
            by_start[x] = by_end[y] = t
            made.append((t, x, y, out))
            # point ``out`` at t across the shared edge (found by its vertices,
            # since the id of the removed triangle may already be reused)
            ov = tv[out]
            j = 0 if ov[0] != x and ov[0] != y else (1 if ov[1] != x and ov[1] != y else 2)
            tn[out][j] = t
        for t, x, y, out in made:
            nbrs = [by_start[y], by_end[x], out]  # across (y, p), (p, x), (x, y)
            if x == g:  # keep the ghost vertex last: (y, p, g)
                tv[t], nbrs = (y, p, x), [nbrs[1], nbrs[2], nbrs[0]]
            elif y == g:  # (p, x, g)
                tv[t], nbrs = (p, x, y), [nbrs[2], nbrs[0], nbrs[1]]
            else:
                self.last = t
            tn[t] = nbrs

    def triangles(self) -> list[tuple[int, int, int]]:
        g = self.g
        return [v for v, ok in zip(self.tv, self.alive) if ok and v[2] != g]


#: Predicates on Python numbers by kind of coordinates: doubles inside the
#: filters' safe range, any doubles, exact ints/Fractions.
_PREDICATES = {
    "tame": (P.orient_xy_tame, P.incircle_xy_tame),
    "float": (P.orient_xy, P.incircle_xy),
    "exact": (P.orient_num, P.incircle_num),
}


def _first_triangle(
    xs: list[Any], ys: list[Any], order: list[int], orient: Any
) -> tuple[int, int, int]:
    """Positions in ``order`` of three points that are not collinear."""
    a, b = order[0], order[1]
    for k in range(2, len(order)):
        c = order[k]
        if orient(xs[a], ys[a], xs[b], ys[b], xs[c], ys[c]) != 0:
            return 0, 1, k
    raise ValueError(
        "`points` must not be all collinear: their Delaunay triangulation has no "
        "triangle."
    )


def delaunay(points: ArrayLike) -> NDArray[np.intp]:
    r"""Delaunay triangulation of a planar point set.

    Parameters
    ----------
    points : array_like, shape (n, 2)
        Finite points with at least three distinct points, not all collinear.
        Repeated points are allowed: the first occurrence (smallest index) is
        used and the later copies are ignored (they appear in no triangle).

    Returns
    -------
    ndarray of intp, shape (m, 3)
        Indices into ``points`` of the triangles, each counter-clockwise.
        When four or more points lie on a common empty circle any of the valid
        triangulations may be returned, but always the same one for the same
        input.

    Raises
    ------
    ValueError
        If ``points`` is not a finite ``(n, 2)`` array, has fewer than three
        distinct points, or all its points are collinear.

    Notes
    -----
    A triangulation is Delaunay when no point lies strictly inside the
    circumcircle of a triangle. Bowyer's and Watson's algorithm inserts the
    points one at a time: the triangles whose circumcircle contains the new
    point ``p`` (tested exactly with :func:`incircle`) form a star-shaped
    cavity around ``p``; they are removed and ``p`` is joined to every edge of
    the cavity's boundary.

    There is no super-triangle: every hull edge ``x -> y`` carries a ghost
    triangle with a vertex at infinity, whose circumcircle is the open
    half-plane outside the edge plus the open edge itself. A point outside the
    current hull is in conflict with the ghosts of the hull edges it sees, so
    the same cavity rule extends the hull, with no far-away vertices whose
    coordinates could spoil a circumcircle.

    The points are inserted in a biased randomised insertion order (seeded,
    so the result is deterministic): random rounds of doubling size, each
    sorted along a Hilbert curve. The triangle in conflict with a new point is
    found by walking from the last new triangle, which is short in that
    order; the expected time is :math:`O(n \log n)`.

    References
    ----------
    .. [1] A. Bowyer, "Computing Dirichlet tessellations", The Computer
       Journal 24(2), 162-166 (1981). :doi:`10.1093/comjnl/24.2.162`
    .. [2] D. F. Watson, "Computing the n-dimensional Delaunay tessellation
       with application to Voronoi polytopes", The Computer Journal 24(2),
       167-172 (1981). :doi:`10.1093/comjnl/24.2.167`
    .. [3] J. R. Shewchuk, "Adaptive precision floating-point arithmetic and
       fast robust geometric predicates", Discrete & Computational Geometry
       18, 305-363 (1997). :doi:`10.1007/PL00009321`
    .. [4] L. Kettner, K. Mehlhorn, S. Pion, S. Schirra and C. Yap, "Classroom
       examples of robustness problems in geometric computations",
       Computational Geometry 40(1), 61-78 (2008).
       :doi:`10.1016/j.comgeo.2007.06.003`

    Examples
    --------
    >>> import numpy as np
    >>> from reference import delaunay, is_delaunay
    >>> pts = np.array([[0, 0], [2, 0], [1, 1.5], [1, -1.5]])
    >>> tri = delaunay(pts)
    >>> sorted(tuple(sorted(t)) for t in tri.tolist())
    [(0, 1, 2), (0, 1, 3)]
    >>> is_delaunay(pts, tri)
    True

    The corners of a square are cocircular; either diagonal is valid:

    >>> square = [[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]  # last one repeated
    >>> tri = delaunay(square)
    >>> tri.shape, is_delaunay(square, tri)
    ((2, 3), True)
    """
    pts, approx = as_exact_points(points, "points")
    ids = P.sorted_unique(pts)
    if ids.size < 3:
        raise ValueError(
            f"`points` must hold at least 3 distinct points; got {ids.size} distinct "
            f"among {pts.shape[0]}."
        )
    uniq = pts[ids]
    order = _brio_order(approx[ids]).tolist()  # any order is correct; rounding is harmless
    xs, ys = uniq[:, 0].tolist(), uniq[:, 1].tolist()
    mode = "exact" if uniq.dtype == object else ("tame" if P.is_tame(uniq) else "float")
    orient = _PREDICATES[mode][0]
    i, j, k = _first_triangle(xs, ys, order, orient)
    a, b, c = order[i], order[j], order[k]
    if orient(xs[a], ys[a], xs[b], ys[b], xs[c], ys[c]) < 0:
        a, b = b, a
    mesh = _Triangulation(xs, ys, mode)
    mesh.start(a, b, c)
    for pos in range(2, len(order)):
        if pos != k:
            mesh.insert(order[pos])
    tri = np.asarray(mesh.triangles(), dtype=np.intp).reshape(-1, 3)
    return ids[tri]


# ---------------------------------------------------------------------------
# Checking a triangulation
# ---------------------------------------------------------------------------


def _as_triangles(triangles: ArrayLike, n: int) -> NDArray[np.int64]:
    """Validate ``triangles`` as an ``(m, 3)`` integer array of indices < ``n``."""
    arr = np.asarray(triangles)
    if arr.size == 0 and arr.ndim in (1, 2) and (arr.ndim == 1 or arr.shape[1] == 3):
        return np.zeros((0, 3), dtype=np.int64)
    if arr.dtype.kind not in "iu":
        raise ValueError(
            f"`triangles` must be an integer array of point indices; got dtype {arr.dtype}."
        )
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"`triangles` must have shape (m, 3); got {arr.shape}.")
    if np.any(arr < 0) or np.any(arr >= n):
        raise ValueError(
            f"`triangles` must hold indices in [0, {n}) for {n} points; got values "
            f"from {arr.min()} to {arr.max()}."
        )
    return arr.astype(np.int64)


def _covers_every_point(pts: NDArray[np.float64], tri: NDArray[np.int64]) -> bool:
    """True when every point equals (in coordinates) some triangle vertex."""
    order = np.lexsort((pts[:, 1], pts[:, 0]))
    sp = pts[order]
    new = np.ones(order.size, dtype=bool)
    new[1:] = np.any(sp[1:] != sp[:-1], axis=1)
    group = np.empty(order.size, dtype=np.int64)
    group[order] = np.cumsum(new) - 1
    used = np.zeros(int(new.sum()), dtype=bool)
    used[group[tri.ravel()]] = True
    return bool(used.all())


def _boundary_is_convex_cycle(pts: NDArray[np.float64], start: NDArray, end: NDArray) -> bool:
    """True when the directed edges ``start -> end`` form one convex ccw cycle."""
    if np.unique(start).size != start.size or np.unique(end).size != end.size:
        return False
    nxt = dict(zip(start.tolist(), end.tolist()))
    cycle = [int(start[0])]
    for _ in range(start.size):
        v = nxt.get(cycle[-1])
        if v is None:
            return False
        cycle.append(v)
    if cycle[-1] != cycle[0] or len(set(cycle[:-1])) != start.size:
        return False
    u = np.asarray(cycle[:-1])
    v, w = np.roll(u, -1), np.roll(u, -2)
    turn = P.orient_many(pts[u], pts[v], pts[w])
    if np.any(turn < 0):
        return False
    d1 = _direction_signs(pts[u], pts[v])
    d2 = np.roll(d1, -1, axis=0)
    # straight on (turn 0) must continue forward, not double back
    if np.any((turn == 0) & np.any(d1 != d2, axis=1)):
        return False
    # Every turn is in [0, pi), so the edge direction winds once around exactly
    # when it passes once from the lower half-plane of directions to the upper.
    upper = (d1[:, 1] > 0) | ((d1[:, 1] == 0) & (d1[:, 0] > 0))
    wraps = np.count_nonzero(~upper & np.roll(upper, -1))
    return wraps == 1


def _direction_signs(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.int8]:
    """Exact signs of the components of ``b - a``, by comparison."""
    return (b > a).astype(np.int8) - (b < a).astype(np.int8)


def is_delaunay(points: ArrayLike, triangles: ArrayLike) -> bool:
    r"""Check that ``triangles`` is a Delaunay triangulation of ``points``.

    Parameters
    ----------
    points : array_like, shape (n, 2)
        Finite points.
    triangles : array_like of int, shape (m, 3)
        Indices into ``points``.

    Returns
    -------
    bool
        True when the triangles are counter-clockwise and non-degenerate, tile
        the convex hull of the points with every distinct point as a vertex
        (a repeated point may be represented by any one of its copies), and
        every interior edge is locally Delaunay. An empty ``triangles`` gives
        False: a point set without three non-collinear points has no
        triangulation here, consistently with :func:`delaunay`.

    Raises
    ------
    ValueError
        If ``points`` is not a finite ``(n, 2)`` array, or ``triangles`` is
        not an integer array of shape ``(m, 3)`` with entries in ``[0, n)``.

    Notes
    -----
    All tests are exact (:func:`reference.orient2d` and
    :func:`incircle`).

    *A triangulation of the hull.* Each directed edge may occur once; an edge
    whose reverse also occurs is interior (shared by exactly two triangles),
    the others are boundary edges. The boundary edges must form one closed
    cycle that only turns left or goes straight on and winds once, i.e. a
    convex polygon :math:`Q`. The triangles, all positively oriented, then
    form a 2-chain whose boundary is :math:`\partial Q`, so they cover every
    point of :math:`Q` exactly once (the winding number): no overlaps, no
    gaps, and the total area equals the area of :math:`Q`. Since every point
    is a vertex, :math:`Q` is the convex hull.

    *Delaunay.* By Delaunay's lemma a triangulation is Delaunay when every
    interior edge is locally Delaunay: for the triangles ``(u, v, w)`` and
    ``(v, u, z)`` sharing the edge, ``z`` is not strictly inside the
    circumcircle of ``u v w``.

    References
    ----------
    .. [1] B. Delaunay, "Sur la sphere vide", Bulletin de l'Academie des
       Sciences de l'URSS 6, 793-800 (1934).
    .. [2] J. R. Shewchuk, "Adaptive precision floating-point arithmetic and
       fast robust geometric predicates", Discrete & Computational Geometry
       18, 305-363 (1997). :doi:`10.1007/PL00009321`
    .. [3] A. Bowyer, "Computing Dirichlet tessellations", The Computer
       Journal 24(2), 162-166 (1981). :doi:`10.1093/comjnl/24.2.162`
    .. [4] D. F. Watson, "Computing the n-dimensional Delaunay tessellation
       with application to Voronoi polytopes", The Computer Journal 24(2),
       167-172 (1981). :doi:`10.1093/comjnl/24.2.167`

    Examples
    --------
    >>> from reference import is_delaunay
    >>> pts = [[0, 0], [2, 0], [1, 1.5], [1, -1.5]]
    >>> is_delaunay(pts, [[0, 1, 2], [1, 0, 3]])
    True
    >>> is_delaunay(pts, [[0, 3, 2], [3, 1, 2]])  # the other diagonal
    False
    >>> is_delaunay(pts, [[0, 2, 1], [1, 0, 3]])  # first one clockwise
    False
    """
    pts, _ = as_exact_points(points, "points")
    tri = _as_triangles(triangles, pts.shape[0])
    if tri.shape[0] == 0:
        return False
    if np.any(P.orient_many(pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]) <= 0):
        return False
    if not _covers_every_point(pts, tri):
        return False
    n = pts.shape[0]
    start = tri.ravel()
    end = np.roll(tri, -1, axis=1).ravel()  # edge i: tri[k, i] -> tri[k, i + 1]
    code = start * n + end
    if np.unique(code).size != code.size:
        return False
    order = np.argsort(code)
    pos = np.searchsorted(code[order], end * n + start)
    pos = np.minimum(pos, code.size - 1)
    twin_found = code[order][pos] == end * n + start
    if not _boundary_is_convex_cycle(pts, start[~twin_found], end[~twin_found]):
        return False
    # local Delaunay test once per interior edge (start < end)
    edge = np.flatnonzero(twin_found & (start < end))
    twin = order[pos[edge]]
    apex = tri.ravel()[(edge // 3) * 3 + (edge % 3 + 2) % 3]
    opposite = tri.ravel()[(twin // 3) * 3 + (twin % 3 + 2) % 3]
    inside = P.incircle_many_ccw(pts[start[edge]], pts[end[edge]], pts[apex], pts[opposite])
    return bool(np.all(inside <= 0))
