"""Bezier curves: Bernstein polynomials, de Casteljau's algorithm, subdivision.

Model solutions for the Bezier part of the geometry-and-interpolation lecture
(its ``eval_bezier`` and the ``quad_demo`` / ``cubic_demo`` pictures of de
Casteljau's construction).

Public functions
----------------
bernstein
    The Bernstein basis polynomial ``B_{i,n}(t)``.
bezier
    Points of a Bezier curve, by de Casteljau's algorithm, vectorised over ``t``.
de_casteljau
    Every level of de Casteljau's triangle at one ``t`` (what the demo draws).
split
    Control polygons of the two pieces of a curve cut at ``t``.

A curve of degree ``n`` in ``R**d`` is given by its control polygon ``ctrl``,
an ``(n + 1, d)`` array. The parameter ``t`` may be any finite real number:
the curve is defined on ``[0, 1]``, and other values extrapolate the same
polynomial (de Casteljau's recurrence stays valid, but it is then no longer a
convex combination and loses its numerical robustness).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from reference._validation import (
    as_finite_array,
    as_nonnegative_int,
    as_parameter,
    as_points,
)

__all__ = ["bernstein", "bezier", "de_casteljau", "split"]

#: Parameter values per chunk in :func:`bezier` (bounds the working triangle).
_CHUNK_POINTS = 2**12
#: Largest binomial coefficient used as a float in :func:`bernstein`; above it
#: the logarithmic form is used. C(1029, 514) ~ 1.4e308 is the last that fits.
_BINOMIAL_MAX = 2**1020
#: A power ``t**i`` or ``(1 - t)**(n - i)`` below this may have lost accuracy to
#: underflow (while the product with the binomial need not be small).
_POWER_MIN = 2.0**-960


def _bernstein_from_logs(
    c: int, i: int, t: NDArray[np.float64], k: int, s: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``c t**i s**k`` as ``sign * exp(log c + i log|t| + k log|s|)`` (``0 log 0 = 0``)."""
    # Imported here: scipy.special costs 0.15 s to import, and every grader that
    # imports ``reference`` would pay it at start-up for this rare branch.
    from scipy.special import xlogy

    sign = np.sign(t) ** i * np.sign(s) ** k
    with np.errstate(under="ignore", over="ignore"):
        return sign * np.exp(math.log(c) + xlogy(i, np.abs(t)) + xlogy(k, np.abs(s)))


def _as_ctrl(ctrl: ArrayLike) -> NDArray[np.float64]:
    return as_points(ctrl, "ctrl", dim=None, min_points=1)


def _as_scalar_t(t: Any) -> float:
    arr, was_scalar = as_parameter(t, "t")
    if not was_scalar:
        raise ValueError(f"`t` must be a single number; got an array of shape {np.shape(t)}.")
    return float(arr[0])


def bernstein(n: int, i: int, t: ArrayLike) -> NDArray[np.float64] | np.float64:
    """Return the Bernstein basis polynomial ``B_{i,n}(t)``.

    Parameters
    ----------
    n : int
        Degree, ``n >= 0``.
    i : int
        Index, ``0 <= i <= n``.
    t : float or array_like
        Parameter value(s), any shape, finite; ``[0, 1]`` is the usual range
        but any real ``t`` is accepted.

    Returns
    -------
    b : numpy.float64 or ndarray
        ``C(n, i) t**i (1 - t)**(n - i)``, with the shape of ``t`` (a
        ``numpy.float64`` for a scalar ``t``).

    Raises
    ------
    ValueError
        If ``n`` or ``i`` is not an integer, ``i`` is outside ``[0, n]``, or
        ``t`` is not finite.

    Notes
    -----
    .. math::

        B_{i,n}(t) = \\binom{n}{i} t^i (1 - t)^{n - i}, \\qquad
        \\sum_{i=0}^{n} B_{i,n}(t) = 1, \\qquad B_{i,n}(t) \\ge 0
        \\text{ on } [0, 1].

    ``0**0`` is taken as ``1``, so ``B_{0,n}(0) = B_{n,n}(1) = 1``. While the
    binomial coefficient fits in a double (``n <= 1029``; the exact integer
    is correctly rounded) the product is formed directly as
    ``(C(n, i) t**i) (1 - t)**(n - i)``, accurate to a few ulps. Where a
    power falls below ``2**-960`` (it may have underflowed although the
    product is representable, e.g. ``B_{90,1500}(1/2) ~ 9e-306``), and for
    every ``t`` when the binomial overflows a double, the value is formed
    from logarithms, ``exp(log C(n, i) + i log|t| + (n - i) log|1 - t|)``
    with the sign restored; its relative error grows like ``eps`` times the
    size of the logarithms (below ``1e-12`` for ``n <= 2000``, checked against
    ``scipy.stats.binom.pmf``, which is the same function on ``[0, 1]``). Far outside
    ``[0, 1]`` the value may overflow to ``inf`` (it is then larger than
    ``1.8e308``).

    References
    ----------
    .. [1] R. T. Farouki, "The Bernstein polynomial basis: A centennial
       retrospective", Computer Aided Geometric Design 29(6), 379-419, 2012.
       :doi:`10.1016/j.cagd.2012.03.001`
    .. [2] G. Farin, "Curves and Surfaces for CAGD: A Practical Guide",
       5th ed., Morgan Kaufmann, 2002.

    Examples
    --------
    >>> import numpy as np
    >>> from reference import bernstein
    >>> bernstein(3, 1, [0.0, 0.5, 1.0]).tolist()
    [0.0, 0.375, 0.0]
    >>> t = np.linspace(0, 1, 5)
    >>> bool(np.allclose(sum(bernstein(4, i, t) for i in range(5)), 1.0))
    True
    """
    n = as_nonnegative_int(n, "n")
    i = as_nonnegative_int(i, "i")
    if i > n:
        raise ValueError(f"`i` must satisfy 0 <= i <= n = {n}; got {i}.")
    tt = as_finite_array(t, "t")
    s = 1.0 - tt
    c = math.comb(n, i)
    if c > _BINOMIAL_MAX:
        b = _bernstein_from_logs(c, i, tt, n - i, s)
    else:
        with np.errstate(under="ignore", over="ignore"):
            ti, si = tt**i, s ** (n - i)
            b = (float(c) * ti) * si
        risky = (np.abs(ti) < _POWER_MIN) | (np.abs(si) < _POWER_MIN)
        if np.any(risky):  # a power near or below underflow: redo from logs
            b = np.where(risky, _bernstein_from_logs(c, i, tt, n - i, s), b)
    b = np.asarray(b, dtype=np.float64)
    return b[()] if b.ndim == 0 else b


def _de_casteljau_vectorised(
    ctrl: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Points of the curve at every ``t`` (1-D), shape ``(t.size, d)``.

    The triangle is kept as ``(n + 1, d, m)`` so that every level is one
    contiguous slice, updated in place as ``(1 - t) P + t Q``.
    """
    m = t.size
    b = np.repeat(ctrl[:, :, None], m, axis=2)
    s = 1.0 - t
    for k in range(ctrl.shape[0] - 1, 0, -1):
        right = b[1 : k + 1] * t  # computed before b[:k] is overwritten
        b[:k] *= s
        b[:k] += right
    return b[0].T


def bezier(ctrl: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Evaluate the Bezier curve with control polygon ``ctrl`` at ``t``.

    Parameters
    ----------
    ctrl : array_like of shape (n + 1, d)
        Control points ``P_0, ..., P_n`` of a curve of degree ``n`` in
        ``R**d`` (``n >= 0``, ``d >= 1``).
    t : float or array_like of shape (m,)
        Parameter value(s); finite. The curve is traced for ``t`` in
        ``[0, 1]``; other values extrapolate.

    Returns
    -------
    points : ndarray of shape (d,) or (m, d)
        ``sum_i B_{i,n}(t) P_i``: one point for a scalar ``t``, one row per
        parameter value otherwise.

    Raises
    ------
    ValueError
        If ``ctrl`` is not a finite ``(n + 1, d)`` array with at least one row,
        or ``t`` is not a finite scalar or 1-D array.

    Notes
    -----
    De Casteljau's algorithm ([2]_) replaces the polygon by
    ``n`` successive levels of convex combinations,

    .. math::

        P_i^{(0)} = P_i, \\qquad
        P_i^{(r)} = (1 - t) P_i^{(r-1)} + t P_{i+1}^{(r-1)}, \\qquad
        r = 1, \\dots, n,

    and returns ``P_0^{(n)}``. This equals ``sum_i B_{i,n}(t) P_i`` but never
    forms a binomial coefficient; for ``t`` in ``[0, 1]`` every step is a
    convex combination, which makes the algorithm numerically stable
    ([1]_) and gives ``P_0`` and ``P_n`` exactly at ``t = 0`` and
    ``t = 1``. It costs ``O(n**2 d)`` per point. The points are processed in
    chunks of ``4096`` parameter values, vectorised over ``t``, so memory
    stays ``O(4096 n d)`` beyond the output; the result is bit for bit the
    last level of :func:`de_casteljau` at the same ``t``.

    References
    ----------
    .. [1] R. T. Farouki, "The Bernstein polynomial basis: A centennial
       retrospective", Computer Aided Geometric Design 29(6), 379-419, 2012.
       :doi:`10.1016/j.cagd.2012.03.001`
    .. [2] G. Farin, "Curves and Surfaces for CAGD: A Practical Guide",
       5th ed., Morgan Kaufmann, 2002.

    Examples
    --------
    The lecture's quadratic at ``t = 0.4``:

    >>> from reference import bezier
    >>> ctrl = [[0.0, 0.0], [1.0, 1.0], [1.2, 0.4]]
    >>> bezier(ctrl, 0.4).round(6).tolist()
    [0.672, 0.544]
    >>> bezier(ctrl, [0.0, 1.0]).tolist()
    [[0.0, 0.0], [1.2, 0.4]]
    """
    points = _as_ctrl(ctrl)
    tt, was_scalar = as_parameter(t, "t")
    out = np.empty((tt.size, points.shape[1]))
    for start in range(0, tt.size, _CHUNK_POINTS):
        stop = min(start + _CHUNK_POINTS, tt.size)
        out[start:stop] = _de_casteljau_vectorised(points, tt[start:stop])
    return out[0] if was_scalar else out


def de_casteljau(ctrl: ArrayLike, t: float) -> list[NDArray[np.float64]]:
    """Return every level of de Casteljau's triangle at one parameter ``t``.

    Parameters
    ----------
    ctrl : array_like of shape (n + 1, d)
        Control points of a curve of degree ``n`` in ``R**d``.
    t : float
        One finite parameter value (``[0, 1]`` for points on the curve).

    Returns
    -------
    levels : list of n + 1 ndarrays
        ``levels[r]`` has shape ``(n + 1 - r, d)`` and holds
        ``P_0^{(r)}, ..., P_{n-r}^{(r)}``; ``levels[0]`` is a copy of ``ctrl``
        and ``levels[n][0]`` is the curve point ``bezier(ctrl, t)`` (bit for
        bit).

    Raises
    ------
    ValueError
        If ``ctrl`` is not a finite ``(n + 1, d)`` array or ``t`` is not a
        single finite number.

    Notes
    -----
    Level ``r`` is ``(1 - t) P_i^{(r-1)} + t P_{i+1}^{(r-1)}``: each new
    point lies the fraction ``t`` along a segment of the previous level's
    polygon. The lecture's ``quad_demo`` draws levels 1 (``ptA``, ``ptB``)
    and 2 (``ptC``); ``cubic_demo`` draws levels 1 to 3. The left and right
    edges of the triangle are the control polygons of the two halves
    (:func:`split`).

    References
    ----------
    .. [1] G. Farin, "Curves and Surfaces for CAGD: A Practical Guide",
       5th ed., Morgan Kaufmann, 2002.
    .. [2] R. T. Farouki, "The Bernstein polynomial basis: A centennial
       retrospective", Computer Aided Geometric Design 29(6), 379-419, 2012.
       :doi:`10.1016/j.cagd.2012.03.001`

    Examples
    --------
    >>> from reference import de_casteljau
    >>> levels = de_casteljau([[0.0, 0.0], [1.0, 1.0], [1.2, 0.4]], 0.5)
    >>> [level.tolist() for level in levels]
    [[[0.0, 0.0], [1.0, 1.0], [1.2, 0.4]], [[0.5, 0.5], [1.1, 0.7]], [[0.8, 0.6]]]
    """
    level = _as_ctrl(ctrl).copy()
    tt = _as_scalar_t(t)
    s = 1.0 - tt
    levels = [level]
    for _ in range(level.shape[0] - 1):
        level = s * level[:-1] + tt * level[1:]
        levels.append(level)
    return levels


def split(ctrl: ArrayLike, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Split a Bezier curve at ``t`` into two curves of the same degree.

    Parameters
    ----------
    ctrl : array_like of shape (n + 1, d)
        Control points of a curve ``C`` of degree ``n``.
    t : float
        Finite split parameter; ``0 < t < 1`` for two genuine pieces.

    Returns
    -------
    left, right : ndarray of shape (n + 1, d)
        Control polygons with ``bezier(left, u) == C(t u)`` and
        ``bezier(right, u) == C(t + (1 - t) u)`` for ``u`` in ``[0, 1]`` (up
        to rounding). ``left[-1]`` and ``right[0]`` are both the point
        ``C(t)``.

    Raises
    ------
    ValueError
        If ``ctrl`` is not a finite ``(n + 1, d)`` array or ``t`` is not a
        single finite number.

    Notes
    -----
    Subdivision ([1]_): the left control points are the first
    points of the de Casteljau levels, ``P_0^{(r)}`` for ``r = 0..n``, and
    the right ones the last points, ``P_{n-r}^{(r)}`` for ``r = n..0``.
    Repeated splitting at ``t = 1/2`` makes the control polygons converge
    to the curve, the basis of adaptive plotting and curve intersection.
    For ``t`` outside ``[0, 1]`` the same formulas reparametrise the
    extension of the curve (``left`` then covers ``C`` on ``[0, t]``).

    References
    ----------
    .. [1] G. Farin, "Curves and Surfaces for CAGD: A Practical Guide",
       5th ed., Morgan Kaufmann, 2002.
    .. [2] R. T. Farouki, "The Bernstein polynomial basis: A centennial
       retrospective", Computer Aided Geometric Design 29(6), 379-419, 2012.
       :doi:`10.1016/j.cagd.2012.03.001`

    Examples
    --------
    >>> from reference import split
    >>> left, right = split([[0.0, 0.0], [1.0, 1.0], [1.2, 0.4]], 0.5)
    >>> left.tolist()
    [[0.0, 0.0], [0.5, 0.5], [0.8, 0.6]]
    >>> right.tolist()
    [[0.8, 0.6], [1.1, 0.7], [1.2, 0.4]]
    """
    levels = de_casteljau(ctrl, t)
    left = np.array([level[0] for level in levels])
    right = np.array([level[-1] for level in reversed(levels)])
    return left, right
