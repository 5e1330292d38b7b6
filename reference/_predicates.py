"""Orientation and in-circle signs shared by :mod:`reference._geometry` and
:mod:`reference._delaunay` (private; the public wrappers live there).

Coordinates come in one of two exact representations, both produced by
:func:`reference._validation.as_exact_points`:

* a ``float64`` array (every input double, and every integer up to ``2**53``,
  is represented exactly): signs are computed by Shewchuk's floating-point
  filter and, when the filter cannot decide, exactly with
  :class:`fractions.Fraction`;
* an ``object`` array of Python ``int`` and :class:`fractions.Fraction`
  (integers beyond ``2**53``, e.g. int64 near ``2**62``, or input mixing them
  with floats): signs are computed directly in exact rational arithmetic.

No well-kept Python library offers vectorised, exact, filtered predicates over
NumPy arrays (the ``robust-predicates`` family is C/Rust/JS only), so they are
written here; the exact fallback is the standard library's rationals.
"""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "CCW_ERRBOUND",
    "ICC_ERRBOUND",
    "ORIENT_LO",
    "ORIENT_HI",
    "INCIRCLE_LO",
    "INCIRCLE_HI",
    "is_exact_objects",
    "to_objects",
    "sign",
    "orient_exact",
    "orient_num",
    "orient_xy",
    "orient_xy_tame",
    "is_tame",
    "orient_many",
    "incircle_num",
    "incircle_exact",
    "incircle_filter",
    "incircle_xy",
    "incircle_xy_tame",
    "incircle_many_ccw",
    "sorted_unique",
]

Number = Any  # float, int or Fraction

# Unit roundoff of IEEE binary64 (Shewchuk's "epsilon").
_EPS = 2.0**-53
# Shewchuk (1997), Section 4.2: |det - fl(det)| <= (3 + 16 eps) eps * detsum.
CCW_ERRBOUND = (3.0 + 16.0 * _EPS) * _EPS
# Shewchuk (1997), Section 4.3: |det - fl(det)| <= (10 + 96 eps) eps * permanent.
ICC_ERRBOUND = (10.0 + 96.0 * _EPS) * _EPS
# The bounds assume no underflow or overflow. They are used only when every
# coordinate difference is zero or lies in [LO, HI]: then every product is a
# normal number and so is the bound itself; otherwise the exact path decides.
ORIENT_LO, ORIENT_HI = 2.0**-450, 2.0**500
INCIRCLE_LO, INCIRCLE_HI = 2.0**-200, 2.0**250


def is_exact_objects(*arrays: NDArray[Any]) -> bool:
    """True when one of ``arrays`` holds Python ints/Fractions (``object`` dtype)."""
    return any(a.dtype == object for a in arrays)


def to_objects(a: NDArray[Any]) -> NDArray[np.object_]:
    """``a`` as an object array of ``int``/``Fraction``, the same values exactly."""
    if a.dtype == object:
        return a
    out = np.empty(a.shape, dtype=object)
    flat = out.reshape(-1)
    for i, v in enumerate(a.reshape(-1).tolist()):
        flat[i] = int(v) if float(v).is_integer() else Fraction(v)
    return out


def sign(value: Number) -> int:
    return (value > 0) - (value < 0)


def _signs(values: NDArray[Any]) -> NDArray[np.int8]:
    return ((values > 0).astype(np.int8) - (values < 0).astype(np.int8)).astype(np.int8)


# ---------------------------------------------------------------------------
# Orientation
# ---------------------------------------------------------------------------


def orient_exact(px: float, py: float, qx: float, qy: float, rx: float, ry: float) -> int:
    """Exact sign of the orientation determinant of doubles, with rationals."""
    frx, fry = Fraction(rx), Fraction(ry)
    return orient_num(Fraction(px), Fraction(py), Fraction(qx), Fraction(qy), frx, fry)


def orient_num(px: Number, py: Number, qx: Number, qy: Number, rx: Number, ry: Number) -> int:
    """Sign of the orientation determinant of exact numbers (int or Fraction)."""
    return sign((px - rx) * (qy - ry) - (py - ry) * (qx - rx))


def _in_orient_range(d: float) -> bool:
    return d == 0.0 or ORIENT_LO <= abs(d) <= ORIENT_HI


def orient_xy(px: float, py: float, qx: float, qy: float, rx: float, ry: float) -> int:
    """Sign of orient2d for Python floats: filter first, exact when unsure."""
    acx = px - rx
    bcx = qx - rx
    acy = py - ry
    bcy = qy - ry
    detleft = acx * bcy
    detright = acy * bcx
    det = detleft - detright
    detsum = abs(detleft) + abs(detright)
    if (
        _in_orient_range(acx)
        and _in_orient_range(bcx)
        and _in_orient_range(acy)
        and _in_orient_range(bcy)
    ):
        if det > CCW_ERRBOUND * detsum or -det > CCW_ERRBOUND * detsum:
            return 1 if det > 0 else -1
        if detsum == 0.0:
            # Both products are exact zeros (no underflow in range).
            return 0
    return orient_exact(px, py, qx, qy, rx, ry)


def orient_xy_tame(px: float, py: float, qx: float, qy: float, rx: float, ry: float) -> int:
    """:func:`orient_xy` without the range checks.

    Only for coordinates accepted by :func:`is_tame`, whose pairwise
    differences are always zero or inside the filter's range.
    """
    acx = px - rx
    bcx = qx - rx
    acy = py - ry
    bcy = qy - ry
    detleft = acx * bcy
    detright = acy * bcx
    det = detleft - detright
    bound = CCW_ERRBOUND * (abs(detleft) + abs(detright))
    if det > bound:
        return 1
    if -det > bound:
        return -1
    if bound == 0.0:
        return 0
    return orient_exact(px, py, qx, qy, rx, ry)


def is_tame(coords: NDArray[Any]) -> bool:
    """True when ``coords`` are doubles with every nonzero ``|c|`` in ``[2**-140, 2**240]``.

    For such data every difference of two coordinates is zero or lies in
    ``[2**-193, 2**241]``, inside the ranges that both filters need, so the
    per-call range checks can be skipped.
    """
    if coords.dtype == object:
        return False
    mag = np.abs(coords)
    nonzero = mag[mag > 0]
    if nonzero.size == 0:
        return True
    return bool(nonzero.min() >= 2.0**-140 and nonzero.max() <= 2.0**240)


def orient_many(p: NDArray[Any], q: NDArray[Any], r: NDArray[Any]) -> NDArray[np.int8]:
    """Orientation signs of the rows of broadcastable ``(..., 2)`` arrays, shape ``(m,)``.

    The arrays are validated already (float64, or object ints/Fractions).
    """
    if is_exact_objects(p, q, r):
        p, q, r = (to_objects(v) for v in (p, q, r))
        p, q, r = (v.reshape(-1, 2) for v in np.broadcast_arrays(p, q, r))
        det = (p[:, 0] - r[:, 0]) * (q[:, 1] - r[:, 1]) - (p[:, 1] - r[:, 1]) * (
            q[:, 0] - r[:, 0]
        )
        return _signs(det)
    p, q, r = (v.reshape(-1, 2) for v in np.broadcast_arrays(p, q, r))
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        acx = p[:, 0] - r[:, 0]
        bcx = q[:, 0] - r[:, 0]
        acy = p[:, 1] - r[:, 1]
        bcy = q[:, 1] - r[:, 1]
        detleft = acx * bcy
        detright = acy * bcx
        det = detleft - detright
        detsum = np.abs(detleft) + np.abs(detright)
        ok = np.ones(det.shape, dtype=bool)
        for d in (acx, bcx, acy, bcy):
            a = np.abs(d)
            ok &= (a == 0.0) | ((a >= ORIENT_LO) & (a <= ORIENT_HI))
        sure = ok & ((np.abs(det) > CCW_ERRBOUND * detsum) | (detsum == 0.0))
    out = np.sign(np.where(sure, det, 0.0)).astype(np.int8)
    for i in np.flatnonzero(~sure):
        out[i] = orient_exact(
            float(p[i, 0]), float(p[i, 1]), float(q[i, 0]),
            float(q[i, 1]), float(r[i, 0]), float(r[i, 1]),
        )  # fmt: skip
    return out


# ---------------------------------------------------------------------------
# In-circle
# ---------------------------------------------------------------------------


def incircle_num(
    ax: Number, ay: Number, bx: Number, by: Number, cx: Number, cy: Number, dx: Number, dy: Number
) -> int:
    """Sign of the in-circle determinant of exact numbers (int or Fraction)."""
    adx, ady = ax - dx, ay - dy
    bdx, bdy = bx - dx, by - dy
    cdx, cdy = cx - dx, cy - dy
    det = (
        (adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
        + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
        + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady)
    )
    return sign(det)


def incircle_exact(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float
) -> int:
    """Exact sign of the in-circle determinant of doubles, with rationals."""
    return incircle_num(*(Fraction(v) for v in (ax, ay, bx, by, cx, cy, dx, dy)))


def incircle_filter(
    adx: Any, ady: Any, bdx: Any, bdy: Any, cdx: Any, cdy: Any
) -> tuple[Any, Any, Any]:
    """Return ``(det, bound, permanent)`` of Shewchuk's in-circle filter."""
    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    cdxady = cdx * ady
    adxcdy = adx * cdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    alift = adx * adx + ady * ady
    blift = bdx * bdx + bdy * bdy
    clift = cdx * cdx + cdy * cdy
    det = alift * (bdxcdy - cdxbdy) + blift * (cdxady - adxcdy) + clift * (adxbdy - bdxady)
    permanent = (
        (abs(bdxcdy) + abs(cdxbdy)) * alift
        + (abs(cdxady) + abs(adxcdy)) * blift
        + (abs(adxbdy) + abs(bdxady)) * clift
    )
    return det, ICC_ERRBOUND * permanent, permanent


def _in_incircle_range(d: float) -> bool:
    return d == 0.0 or INCIRCLE_LO <= abs(d) <= INCIRCLE_HI


def incircle_xy(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float
) -> int:
    """In-circle sign for Python floats, ``a, b, c`` counter-clockwise."""
    adx, ady, bdx, bdy, cdx, cdy = ax - dx, ay - dy, bx - dx, by - dy, cx - dx, cy - dy
    if all(_in_incircle_range(v) for v in (adx, ady, bdx, bdy, cdx, cdy)):
        det, bound, permanent = incircle_filter(adx, ady, bdx, bdy, cdx, cdy)
        if det > bound:
            return 1
        if -det > bound:
            return -1
        if permanent == 0.0:
            return 0
    return incircle_exact(ax, ay, bx, by, cx, cy, dx, dy)


def incircle_xy_tame(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float, dx: float, dy: float
) -> int:
    """:func:`incircle_xy` without range checks, for data accepted by :func:`is_tame`."""
    adx = ax - dx
    ady = ay - dy
    bdx = bx - dx
    bdy = by - dy
    cdx = cx - dx
    cdy = cy - dy
    bdxcdy = bdx * cdy
    cdxbdy = cdx * bdy
    cdxady = cdx * ady
    adxcdy = adx * cdy
    adxbdy = adx * bdy
    bdxady = bdx * ady
    alift = adx * adx + ady * ady
    blift = bdx * bdx + bdy * bdy
    clift = cdx * cdx + cdy * cdy
    det = alift * (bdxcdy - cdxbdy) + blift * (cdxady - adxcdy) + clift * (adxbdy - bdxady)
    bound = ICC_ERRBOUND * (
        (abs(bdxcdy) + abs(cdxbdy)) * alift
        + (abs(cdxady) + abs(adxcdy)) * blift
        + (abs(adxbdy) + abs(bdxady)) * clift
    )
    if det > bound:
        return 1
    if -det > bound:
        return -1
    if bound == 0.0:
        return 0
    return incircle_exact(ax, ay, bx, by, cx, cy, dx, dy)


def incircle_many_ccw(
    a: NDArray[Any], b: NDArray[Any], c: NDArray[Any], d: NDArray[Any]
) -> NDArray[np.int8]:
    """In-circle signs of the rows, ``a, b, c`` counter-clockwise, shape ``(m,)``."""
    if is_exact_objects(a, b, c, d):
        a, b, c, d = (to_objects(v) for v in (a, b, c, d))
        a, b, c, d = (v.reshape(-1, 2) for v in np.broadcast_arrays(a, b, c, d))
        det, _, _ = incircle_filter(
            a[:, 0] - d[:, 0], a[:, 1] - d[:, 1], b[:, 0] - d[:, 0],
            b[:, 1] - d[:, 1], c[:, 0] - d[:, 0], c[:, 1] - d[:, 1],
        )  # fmt: skip
        return _signs(det)
    a, b, c, d = (v.reshape(-1, 2) for v in np.broadcast_arrays(a, b, c, d))
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        diffs = [a[:, 0] - d[:, 0], a[:, 1] - d[:, 1], b[:, 0] - d[:, 0],
                 b[:, 1] - d[:, 1], c[:, 0] - d[:, 0], c[:, 1] - d[:, 1]]  # fmt: skip
        ok = np.ones(a.shape[0], dtype=bool)
        for v in diffs:
            m = np.abs(v)
            ok &= (m == 0.0) | ((m >= INCIRCLE_LO) & (m <= INCIRCLE_HI))
        det, bound, permanent = incircle_filter(*diffs)
        sure = ok & ((np.abs(det) > bound) | (permanent == 0.0))
    out = np.sign(np.where(sure, det, 0.0)).astype(np.int8)
    rows = np.concatenate([a, b, c, d], axis=1)
    for i in np.flatnonzero(~sure):
        out[i] = incircle_exact(*rows[i].tolist())
    return out


# ---------------------------------------------------------------------------
# Shared by the hull and the triangulation
# ---------------------------------------------------------------------------


def sorted_unique(points: NDArray[Any]) -> NDArray[np.intp]:
    """Indices of the distinct points in lexicographic order (x, then y).

    Among equal points the smallest index is kept (``np.lexsort`` is stable).
    Works on float64 and on exact object coordinates (compared exactly).
    """
    order = np.lexsort((points[:, 1], points[:, 0]))
    sp = points[order]
    keep = np.ones(order.size, dtype=bool)
    keep[1:] = np.any(sp[1:] != sp[:-1], axis=1)
    return order[keep]
