"""Polynomial interpolation in barycentric form: nodes, weights, evaluation.

Model solutions for the interpolation part of the geometry-and-interpolation
lecture (its ``LagrangeInterp1D``, ``EquispacedNodes`` and
``EquispacedBarWeights`` demo and the Runge phenomenon it shows).

Public functions
----------------
equispaced_nodes, chebyshev_nodes
    ``n + 1`` nodes on ``[-1, 1]`` in ascending order.
equispaced_weights, chebyshev_weights, barycentric_weights
    Barycentric weights, for the two node families in closed form and for any
    distinct nodes by the product formula.
barycentric_interpolate
    The second (true) barycentric formula, vectorised and evaluated in chunks;
    outside the nodes the first form and the Newton form (see its Notes).
lebesgue_constant
    The maximum of the Lebesgue function between the extreme nodes.

Conventions shared by every function here: weights have an arbitrary common
scale (the barycentric formula does not see it); the weights this module
computes are scaled so that ``max |w| == 1`` and the weight of the leftmost
node is positive, so for ascending nodes the signs are ``(-1)**j``. Weights
whose exact value would fall below the smallest normal double
(``sys.float_info.min``, about ``2.2e-308``) are returned as that value with
the right sign, so that every weight is finite, non-zero and normal.
"""

from __future__ import annotations

import math
import numbers
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from reference._validation import (
    as_abscissae,
    as_finite_array,
    as_nonnegative_int,
    shift_parameter,
)

__all__ = [
    "equispaced_nodes",
    "chebyshev_nodes",
    "equispaced_weights",
    "chebyshev_weights",
    "barycentric_weights",
    "barycentric_interpolate",
    "lebesgue_constant",
]

#: Unit roundoff of IEEE binary64.
_UNIT_ROUNDOFF = 2.0**-53
#: Smallest positive normal double: the floor for the magnitude of a weight.
_TINY = sys.float_info.min
#: Evaluation points per chunk (at most); bounds the temporary matrix. Chunks
#: of 2**11 to 2**14 points run equally fast (within 15 %); smaller ones stay in
#: cache.
_CHUNK_POINTS = 2**12
#: Elements of the (points x nodes) temporary per chunk (at most): 4 MiB.
_CHUNK_ELEMENTS = 2**19
#: Interior samples of the Lebesgue function on the whole interval (at least).
_LEBESGUE_SAMPLES = 4096
#: Interior samples per gap between consecutive nodes (at least).
_LEBESGUE_PER_GAP = 16
#: Golden-section steps refining the maximum inside each gap.
_GOLDEN_STEPS = 48


# --------------------------------------------------------------------------
# Validation helpers private to this module
# --------------------------------------------------------------------------


def _as_degree(n: Any) -> int:
    return as_nonnegative_int(n, "n", minimum=1)


def _as_kind(kind: Any) -> int:
    if isinstance(kind, bool) or not isinstance(kind, numbers.Integral) or kind not in (1, 2):
        raise ValueError(
            f"`kind` must be 1 (Chebyshev points of the first kind, the roots) or "
            f"2 (of the second kind, the extrema); got {kind!r}."
        )
    return int(kind)


def _as_nodes(nodes: ArrayLike) -> tuple[NDArray[np.float64], int]:
    """Finite, non-empty, 1-D, pairwise distinct nodes (any order), and their origin.

    Integers beyond ``2**53`` are shifted by an integer origin first (see
    :func:`reference._validation.as_abscissae`), so distinct integers stay
    distinct; the interpolant is translation invariant.
    """
    x, origin = as_abscissae(nodes, "nodes", ndim=1)
    if x.size == 0:
        raise ValueError("`nodes` must hold at least one node; got an empty array.")
    order = np.argsort(x, kind="stable")
    same = np.flatnonzero(x[order[1:]] == x[order[:-1]])
    if same.size:
        i, j = sorted((int(order[same[0]]), int(order[same[0] + 1])))
        if origin:
            raise ValueError(
                f"`nodes` must be distinct in double precision; nodes[{i}] and "
                f"nodes[{j}] are distinct integers, but the nodes span too wide a range "
                "for their differences to be told apart as doubles. Rescale the nodes."
            )
        raise ValueError(
            f"`nodes` must be pairwise distinct; "
            f"nodes[{i}] == nodes[{j}] == {float(x[i])!r}."
        )
    return x, origin


def _as_values(values: ArrayLike, n_nodes: int) -> NDArray[np.float64]:
    """``values`` as an ``(n_nodes, d)`` array (``d = 1`` for scalar data)."""
    y = as_finite_array(values, "values")
    if y.ndim not in (1, 2) or y.shape[0] != n_nodes:
        raise ValueError(
            f"`values` must have shape ({n_nodes},) or ({n_nodes}, d), one row per "
            f"node; got {y.shape}."
        )
    return y.reshape(n_nodes, -1)


def _as_weights(weights: ArrayLike | None, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Validated weights, rescaled by a power of two so that max |w| is in [0.5, 1).

    The rescaling is exact (barring weights spanning more than the whole
    exponent range) and harmless, since the formula ignores a common factor;
    it keeps ``w / (t - x_j)`` away from overflow for user weights such as
    the lecture's raw binomial coefficients.
    """
    if weights is None:
        return barycentric_weights(x)
    w = as_finite_array(weights, "weights", ndim=1)
    if w.shape != x.shape:
        raise ValueError(
            f"`weights` must have one entry per node, shape {x.shape}; got {w.shape}."
        )
    zero = np.flatnonzero(w == 0)
    if zero.size:
        raise ValueError(
            f"`weights` must be non-zero (a zero weight drops its node); "
            f"weights[{int(zero[0])}] == 0."
        )
    _, top = np.frexp(np.max(np.abs(w)))
    return np.ldexp(w, -int(top))


# --------------------------------------------------------------------------
# Nodes
# --------------------------------------------------------------------------


def _odd_sine_nodes(n: int, denominator: int) -> NDArray[np.float64]:
    """``sin(pi * k / denominator)`` for ``k = -n, -n + 2, ..., n``, exactly odd."""
    k = np.arange(-n, n + 1, 2)
    return np.sign(k) * np.sin(np.pi * np.abs(k) / denominator)


def equispaced_nodes(n: int) -> NDArray[np.float64]:
    """Return the ``n + 1`` equispaced nodes ``x_j = -1 + 2 j / n`` on ``[-1, 1]``.

    Parameters
    ----------
    n : int
        Polynomial degree, ``n >= 1``.

    Returns
    -------
    nodes : ndarray of shape (n + 1,)
        Ascending nodes; ``nodes[0] == -1``, ``nodes[-1] == 1`` and
        ``nodes[n - j] == -nodes[j]`` hold exactly.

    Raises
    ------
    ValueError
        If ``n`` is not an integer ``>= 1``.

    Notes
    -----
    Each node is computed as ``(2 j - n) / n``: the numerator is an exact
    integer and the division is correctly rounded, which makes the set exactly
    symmetric about 0 and hits ``0`` exactly when ``n`` is even. ``n = 0``
    (a single node) is rejected, as in :func:`chebyshev_nodes`, since the
    family is not defined by a degree-0 formula; pass ``[0.0]`` to
    :func:`barycentric_interpolate` directly for a constant interpolant.

    Interpolation in these nodes is exponentially ill-conditioned: the
    Lebesgue constant grows like ``2**(n + 1) / (e n log n)`` (Runge's
    phenomenon, see :func:`lebesgue_constant`).

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`

    Examples
    --------
    >>> from reference import equispaced_nodes
    >>> equispaced_nodes(4).tolist()
    [-1.0, -0.5, 0.0, 0.5, 1.0]
    """
    n = _as_degree(n)
    j = np.arange(n + 1, dtype=np.float64)
    return (2.0 * j - n) / n


def chebyshev_nodes(n: int, kind: int = 2) -> NDArray[np.float64]:
    """Return ``n + 1`` Chebyshev points on ``[-1, 1]`` in ascending order.

    Parameters
    ----------
    n : int
        Polynomial degree, ``n >= 1``.
    kind : {2, 1}, optional
        ``2`` (default): Chebyshev points of the second kind (the extrema of
        ``T_n``), ``x_j = -cos(j pi / n)``. ``1``: points of the first kind
        (the roots of ``T_{n+1}``), ``x_j = -cos((2 j + 1) pi / (2 n + 2))``.

    Returns
    -------
    nodes : ndarray of shape (n + 1,)
        Ascending nodes, exactly symmetric: ``nodes[n - j] == -nodes[j]``.
        For ``kind=2`` the end points are exactly ``-1.0`` and ``1.0``.

    Raises
    ------
    ValueError
        If ``n`` is not an integer ``>= 1`` or ``kind`` is not 1 or 2.

    Notes
    -----
    The cosines are rewritten as sines of a symmetric argument,

    .. math::

        -\\cos\\frac{j\\pi}{n} = \\sin\\frac{(2j - n)\\pi}{2n}, \\qquad
        -\\cos\\frac{(2j + 1)\\pi}{2n + 2} = \\sin\\frac{(2j - n)\\pi}{2n + 2},

    and the sine is evaluated at ``|2 j - n|`` and given the sign of
    ``2 j - n``. Hence the nodes are exactly symmetric and the middle node is
    exactly ``0`` when ``n`` is even (``-cos`` would give ``-6.1e-17``).
    ``n = 0`` is rejected: ``-cos(0 pi / 0)`` is undefined for ``kind=2``.

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`

    Examples
    --------
    >>> from reference import chebyshev_nodes
    >>> chebyshev_nodes(4).round(6).tolist()
    [-1.0, -0.707107, 0.0, 0.707107, 1.0]
    >>> chebyshev_nodes(1, kind=1).round(6).tolist()
    [-0.707107, 0.707107]
    """
    n = _as_degree(n)
    kind = _as_kind(kind)
    if kind == 1:
        return _odd_sine_nodes(n, 2 * n + 2)
    x = _odd_sine_nodes(n, 2 * n)
    x[0], x[-1] = -1.0, 1.0
    return x


# --------------------------------------------------------------------------
# Weights
# --------------------------------------------------------------------------


def _clamp_tiny(w: NDArray[np.float64]) -> NDArray[np.float64]:
    """Replace weights below the smallest normal double by +-that value."""
    small = np.abs(w) < _TINY
    w[small] = np.copysign(_TINY, w[small])
    return w


def equispaced_weights(n: int) -> NDArray[np.float64]:
    """Return barycentric weights for :func:`equispaced_nodes`, ``max |w| = 1``.

    Parameters
    ----------
    n : int
        Polynomial degree, ``n >= 1``.

    Returns
    -------
    weights : ndarray of shape (n + 1,)
        ``w_j = (-1)**j * C(n, j) / C(n, n // 2)``, each correctly rounded,
        except that magnitudes below ``sys.float_info.min`` (``2.2e-308``)
        are returned as ``+-sys.float_info.min``. Always finite and non-zero.

    Raises
    ------
    ValueError
        If ``n`` is not an integer ``>= 1``.

    Notes
    -----
    For ``x_j = -1 + 2 j / n`` the weights ``1 / prod_{k != j}(x_j - x_k)``
    are proportional to ``(-1)**j C(n, j)`` ([1]_). The lecture
    computes ``binomial(n, j)`` directly, which overflows a double for
    ``n > 1029``. Here the binomials are exact Python integers, built by the
    recurrence ``C(n, j + 1) = C(n, j) (n - j) / (j + 1)``, and each ratio
    ``C(n, j) / C(n, n // 2)`` is formed by Python's correctly rounded
    integer true division. The cost is ``O(n**2)`` bit operations, a few
    milliseconds for ``n = 5000`` and about 2 s for ``n = 100000``.

    The smallest ratio, ``C(n, 0) / C(n, n // 2)``, is about
    ``2**-n sqrt(pi n / 2)``; it stays above the smallest normal double up to
    ``n = 1027``, so for ``n <= 1027`` every weight is the exact ratio
    correctly rounded. Beyond that the outermost weights are clamped to
    ``+-2.2e-308``: they keep their signs and the interpolation property
    (the second barycentric form with any non-zero weights still reproduces
    every data value at its node), but the interpolant is then a rational
    function rather than the polynomial. At such degrees the equispaced
    polynomial interpolant is meaningless anyway: its Lebesgue constant
    exceeds ``1e300``.

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`

    Examples
    --------
    >>> from reference import equispaced_weights
    >>> equispaced_weights(4).tolist()
    [0.16666666666666666, -0.6666666666666666, 1.0, -0.6666666666666666, 0.16666666666666666]
    >>> w = equispaced_weights(3000)
    >>> bool(w.min() < 0 < w.max()), float(abs(w).min()) == 2.2250738585072014e-308
    (True, True)
    """
    n = _as_degree(n)
    half = n // 2
    binomials = [1]
    for j in range(half):
        binomials.append(binomials[-1] * (n - j) // (j + 1))
    middle = binomials[-1]
    ratios = [c / middle for c in binomials]  # correctly rounded, may underflow
    magnitude = np.array(ratios + ratios[n - half - 1 :: -1], dtype=np.float64)
    sign = np.where(np.arange(n + 1) % 2 == 0, 1.0, -1.0)
    return _clamp_tiny(sign * magnitude)


def chebyshev_weights(n: int, kind: int = 2) -> NDArray[np.float64]:
    """Return barycentric weights for :func:`chebyshev_nodes` (Salzer's formulas).

    Parameters
    ----------
    n : int
        Polynomial degree, ``n >= 1``.
    kind : {2, 1}, optional
        Node family, as in :func:`chebyshev_nodes`.

    Returns
    -------
    weights : ndarray of shape (n + 1,)
        ``kind=2``: ``w_j = (-1)**j``, halved for ``j = 0`` and ``j = n``.
        ``kind=1``: ``w_j = (-1)**j sin((2 j + 1) pi / (2 n + 2))``.
        In both cases ``|w_j| <= 1`` and ``|w_j| == |w_{n-j}|`` exactly.

    Raises
    ------
    ValueError
        If ``n`` is not an integer ``>= 1`` or ``kind`` is not 1 or 2.

    Notes
    -----
    After cancelling the factors common to all ``j``, the weights
    ``1 / prod_{k != j}(x_j - x_k)`` of the Chebyshev points reduce to the
    closed forms above (Salzer [2]_; see also [1]_). They are
    returned exactly as these formulas (common scale 1, not renormalised):
    for ``kind=1`` the largest magnitude is ``cos(pi / (2 n + 2))`` when
    ``n`` is odd. The sine is evaluated as ``cos((2 j - n) pi / (2 n + 2))``
    at ``|2 j - n|`` so that the weights are exactly symmetric.

    The ratio of the largest to the smallest weight is at most ``2`` (kind 2)
    or about ``2 (n + 1) / pi`` (kind 1): no overflow or underflow for any
    ``n``, and interpolation in these points is well conditioned (Lebesgue
    constant ``~ (2 / pi) log n``).

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`
    .. [2] H. E. Salzer, "Lagrangian interpolation at the Chebyshev points
       x_{n,nu} = cos(nu pi / n), nu = 0(1)n; some unnoted advantages",
       The Computer Journal 15(2), 156-159, 1972. :doi:`10.1093/comjnl/15.2.156`

    Examples
    --------
    >>> from reference import chebyshev_weights
    >>> chebyshev_weights(4).tolist()
    [0.5, -1.0, 1.0, -1.0, 0.5]
    >>> chebyshev_weights(2, kind=1).round(6).tolist()
    [0.5, -1.0, 0.5]
    """
    n = _as_degree(n)
    kind = _as_kind(kind)
    j = np.arange(n + 1)
    sign = np.where(j % 2 == 0, 1.0, -1.0)
    if kind == 1:
        return sign * np.cos(np.pi * np.abs(2 * j - n) / (2 * n + 2))
    sign[[0, -1]] *= 0.5
    return sign


def barycentric_weights(nodes: ArrayLike) -> NDArray[np.float64]:
    """Return barycentric weights for arbitrary distinct nodes, ``max |w| = 1``.

    Parameters
    ----------
    nodes : array_like of shape (n + 1,)
        Pairwise distinct, finite nodes in any order (``n + 1 >= 1``).

    Returns
    -------
    weights : ndarray of shape (n + 1,)
        ``w_j`` proportional to ``1 / prod_{k != j}(x_j - x_k)``, scaled so
        that ``max |w_j| == 1`` and the weight of the smallest node is
        positive (for ascending nodes the signs are ``(-1)**j``). Magnitudes
        below ``sys.float_info.min`` are returned as ``+-sys.float_info.min``.
        A single node gets the weight ``[1.0]``.

    Raises
    ------
    ValueError
        If ``nodes`` is not a non-empty 1-D array of finite numbers, or if two
        nodes are equal (the message names both indices).

    Notes
    -----
    The weights are ([1]_)

    .. math::

        w_j = \\frac{1}{\\prod_{k \\ne j} (x_j - x_k)} .

    The differences are multiplied by the inverse capacity ``4 / (b - a)``
    of the interval ``[a, b] = [min x, max x]`` ([1]_, p. 510), rounded to a
    power of two so that the scaling adds no rounding error. The product is
    carried as a mantissa and a separate integer exponent (``numpy.frexp``
    after every factor), the exact form of "log-magnitude and sign": it can
    neither overflow nor underflow whatever the number or spacing of the
    nodes, and each product has a relative error of at most about
    ``n eps`` ([2]_ shows this suffices for the stability of the second
    barycentric form). The largest weight is then scaled to ``+-1``.
    Cost: ``O(n**2)`` operations, ``O(n)`` memory.

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`
    .. [2] N. J. Higham, "The numerical stability of barycentric Lagrange
       interpolation", IMA Journal of Numerical Analysis 24(4), 547-556,
       2004. :doi:`10.1093/imanum/24.4.547`

    Examples
    --------
    >>> from reference import barycentric_weights
    >>> barycentric_weights([-1.0, 0.0, 1.0]).tolist()
    [0.5, -1.0, 0.5]
    >>> barycentric_weights([0.0, 2.0, 1.0]).tolist()
    [0.5, 0.5, -1.0]
    """
    x, _ = _as_nodes(nodes)
    if x.size == 1:
        return np.ones(1)
    # Inverse capacity 4 / (b - a) rounded to a power of two: exact scaling.
    _, e = np.frexp(4.0 / (np.max(x) - np.min(x)))
    mantissa = np.ones_like(x)
    exponent = np.zeros(x.shape, dtype=np.int64)
    for k in range(x.size):
        factor = np.ldexp(x - x[k], int(e) - 1)
        factor[k] = 1.0
        mantissa, step = np.frexp(mantissa * factor)
        exponent += step
    # 1 / (m 2**e) = (1 / m) 2**-e with 1 / m in (1, 2] in magnitude.
    inverse, step = np.frexp(1.0 / mantissa)
    exponent = step - exponent
    # Largest weight: largest exponent, then largest mantissa (exact comparison).
    top = int(np.argmax(np.where(exponent == exponent.max(), np.abs(inverse), 0.0)))
    w = np.ldexp(inverse, exponent - exponent[top]) / abs(inverse[top])
    if w[np.argmin(x)] < 0:
        w = -w
    return _clamp_tiny(w)


# --------------------------------------------------------------------------
# Evaluation
# --------------------------------------------------------------------------


def _chunks(n_points: int, n_nodes: int) -> Iterator[slice]:
    """Slices of at most ``_CHUNK_POINTS`` points and ``_CHUNK_ELEMENTS`` products."""
    size = max(1, min(_CHUNK_POINTS, _CHUNK_ELEMENTS // n_nodes))
    for start in range(0, n_points, size):
        yield slice(start, min(start + size, n_points))


def _rescaled_terms(
    x: NDArray[np.float64], w: NDArray[np.float64], t: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """Terms ``w_j / (t - x_j)`` multiplied by the smallest ``|t - x_j|`` per row.

    The factor cancels between numerator and denominator; after it every
    ``|(t - x_{j*}) / (t - x_j)| <= 1``, so nothing overflows even when ``t``
    is within a subnormal distance of a node. Also returns the nearest node
    index per row; the row of an exact hit (difference 0) is all zeros.
    """
    diff = t[:, None] - x[None, :]
    nearest = np.argmin(np.abs(diff), axis=1)
    closest = np.take_along_axis(diff, nearest[:, None], axis=1)
    with np.errstate(invalid="ignore"):
        terms = w * (closest / diff)
    terms[closest[:, 0] == 0] = 0.0
    terms[np.arange(t.size), nearest] = w[nearest]
    return terms, nearest


def _interpolate_chunk(
    x: NDArray[np.float64],
    w: NDArray[np.float64],
    y1: NDArray[np.float64],
    t: NDArray[np.float64],
    buf: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Second barycentric form for one chunk; ``y1`` is ``[values, 1]``."""
    q = buf[: t.size]
    np.subtract(t[:, None], x[None, :], out=q)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        np.divide(w, q, out=q)
        sums = q @ y1  # numerators and, in the last column, the denominator
        out = sums[:, :-1] / sums[:, -1:]
    bad = np.flatnonzero(~np.isfinite(out).all(axis=1))
    if bad.size:  # an exact node, or an overflow right next to one
        out[bad] = _interpolate_near_nodes(x, w, y1[:, :-1], t[bad])
    return out


def _interpolate_near_nodes(
    x: NDArray[np.float64],
    w: NDArray[np.float64],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
) -> NDArray[np.float64]:
    terms, nearest = _rescaled_terms(x, w, t)
    out = (terms @ y) / terms.sum(axis=1)[:, None]
    hit = t == x[nearest]
    out[hit] = y[nearest[hit]]  # the data value itself, bit for bit
    return out


#: User weights count as the polynomial's (up to a common factor) when they
#: agree with the product formula to this relative accuracy; both are
#: accurate to a few hundred eps for any reasonable degree.
_POLYNOMIAL_WEIGHTS_RTOL = 1e-8


def _are_polynomial_weights(x: NDArray[np.float64], w: NDArray[np.float64]) -> bool:
    """True when ``w`` are the polynomial weights of ``x`` up to a common factor."""
    exact = barycentric_weights(x)
    k = int(np.argmax(np.abs(exact)))
    scaled = w * (exact[k] / w[k])
    return bool(np.all(np.abs(scaled - exact) <= _POLYNOMIAL_WEIGHTS_RTOL * np.abs(exact)))


def _newton_coefficients(
    x: NDArray[np.float64], y: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Divided differences ``f[x_0], f[x_0, x_1], ..., f[x_0..x_n]``, rows of ``(n + 1, d)``."""
    c = y.astype(np.float64, copy=True)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for k in range(1, x.size):
            c[k:] = (c[k:] - c[k - 1 : -1]) / (x[k:] - x[:-k])[:, None]
    return c


def _scaled_difference(
    t: NDArray[np.float64], xk: float
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``t - xk`` as mantissa and exponent (``numpy.frexp``), even when it overflows."""
    with np.errstate(over="ignore"):
        d = t - xk
    big = ~np.isfinite(d)
    d[big] = 0.5 * t[big] - 0.5 * xk
    m, e = np.frexp(d)
    e = e.astype(np.int64)
    e[big] += 1
    return m, e


def _newton_horner(
    x: NDArray[np.float64], c: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Nested Newton form ``c_0 + (t - x_0)(c_1 + (t - x_1)(...))`` at ``t``.

    The running value is kept as a mantissa in ``[0.5, 1)`` and a separate
    int64 exponent, so no intermediate overflows or underflows; only the
    final result is rounded into the double range (to infinity when the true
    value is beyond it).
    """
    zm, ze = np.frexp(np.broadcast_to(c[-1], (t.size, c.shape[1])))
    ze = ze.astype(np.int64)
    for k in range(x.size - 2, -1, -1):
        dm, de = _scaled_difference(t, float(x[k]))
        zm, step = np.frexp(zm * dm[:, None])
        ze = ze + step + de[:, None]
        cm, ce = np.frexp(c[k])
        ce = np.broadcast_to(ce.astype(np.int64), ze.shape)
        top = np.maximum(ze, ce)
        with np.errstate(under="ignore"):
            total = np.ldexp(zm, np.maximum(ze - top, -2000)) + np.ldexp(
                np.broadcast_to(cm, zm.shape), np.maximum(ce - top, -2000)
            )
        zm, step = np.frexp(total)
        ze = np.where(zm == 0, 0, top + step)
    with np.errstate(over="ignore", under="ignore"):
        return np.ldexp(zm, np.clip(ze, -3000, 3000))


def _newton_form(
    x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Ascending nodes and their divided differences, or None if one is not finite.

    Divided differences of very high degree can overflow; the caller then
    keeps the second barycentric formula everywhere.
    """
    order = np.argsort(x, kind="stable")
    c = _newton_coefficients(x[order], y[order])
    if not np.all(np.isfinite(c)):
        return None
    return x[order], c


def _true_weights(x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Unscaled weights ``1 / prod_{k != j} (x_j - x_k)`` as mantissa and int64 exponent."""
    mantissa = np.ones_like(x)
    exponent = np.zeros(x.shape, dtype=np.int64)
    for k in range(x.size):
        dm, de = _scaled_difference(x, float(x[k]))
        dm[k], de[k] = 0.5, 1  # the factor 1 for j == k
        mantissa, step = np.frexp(mantissa * dm)
        exponent += step + de
    inverse, step = np.frexp(1.0 / mantissa)
    return inverse, step - exponent


def _first_form(
    x: NDArray[np.float64],
    weights: tuple[NDArray[np.float64], NDArray[np.int64]],
    y: NDArray[np.float64],
    t: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """First (modified Lagrange) form at ``t`` (no node), and its error bound.

    Returns ``(p, bound)`` with ``p = sum_j l_j(t) f_j`` where ``l_j(t) = w_j
    prod_{k != j} (t - x_k)``, every factor carried as mantissa and exponent so
    nothing overflows before the final scaling, and ``bound = (5n + 5) u
    sum_j |l_j(t) f_j|`` (Higham 2004, backward stability of the first form).
    """
    wm, we = weights
    dm = np.empty((t.size, x.size))
    de = np.empty((t.size, x.size), dtype=np.int64)
    for k in range(x.size):
        dm[:, k], de[:, k] = _scaled_difference(t, float(x[k]))
    lm, le = np.ones(t.size), np.zeros(t.size, dtype=np.int64)
    for k in range(x.size):  # l(t) = prod_k (t - x_k)
        lm, step = np.frexp(lm * dm[:, k])
        le += step + de[:, k]
    bm, step = np.frexp(wm[None, :] * lm[:, None] / dm)
    be = step + we[None, :] + le[:, None] - de
    top = be.max(axis=1)
    with np.errstate(under="ignore", over="ignore"):
        scaled = np.ldexp(bm, np.maximum(be - top[:, None], -2000))
        p = np.ldexp(scaled @ y, np.clip(top, -3000, 3000)[:, None])
        size = np.ldexp(np.abs(scaled) @ np.abs(y), np.clip(top, -3000, 3000)[:, None])
    return p, (5 * x.size) * _UNIT_ROUNDOFF * size


def _extrapolate(
    x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The interpolant at points ``t`` outside ``[min(x), max(x)]``.

    The first form is backward stable (error at most ``bound``); the Newton
    form is often far more accurate (exact for data of low degree) but has no
    such guarantee. Each value is taken from the Newton form when it lies
    within ``bound`` of the first form, else from the first form, so the error
    never exceeds ``2 bound``.
    """
    weights = _true_weights(x)
    newton = _newton_form(x, y)
    out = np.empty((t.size, y.shape[1]))
    for piece in _chunks(t.size, x.size):
        p, bound = _first_form(x, weights, y, t[piece])
        if newton is None:
            out[piece] = p
            continue
        q = _newton_horner(*newton, t[piece])
        with np.errstate(invalid="ignore"):
            agree = np.isfinite(q) & (np.abs(q - p) <= bound)
        out[piece] = np.where(agree, q, p)
    return out


def barycentric_interpolate(
    nodes: ArrayLike,
    values: ArrayLike,
    t: ArrayLike,
    weights: ArrayLike | None = None,
) -> NDArray[np.float64] | np.float64:
    """Evaluate the polynomial interpolant by the second barycentric formula.

    Parameters
    ----------
    nodes : array_like of shape (n + 1,)
        Pairwise distinct, finite interpolation nodes, in any order.
    values : array_like of shape (n + 1,) or (n + 1, d)
        Data at the nodes; a 2-D array interpolates ``d`` components at once
        (a curve in ``R**d``).
    t : float or array_like
        Evaluation point(s), any shape. Points outside ``[min(nodes),
        max(nodes)]`` are accepted (extrapolation, see Notes).
    weights : array_like of shape (n + 1,), optional
        Barycentric weights for ``nodes`` in any common scale, all non-zero,
        e.g. from :func:`chebyshev_weights`. Default:
        ``barycentric_weights(nodes)``.

    Returns
    -------
    p : numpy.float64 or ndarray
        The interpolant at ``t``: shape ``t.shape + values.shape[1:]``; a
        scalar ``t`` with 1-D ``values`` gives a ``numpy.float64``. Where
        ``t`` equals a node ``x_j`` the result is ``values[j]`` exactly (bit
        for bit).

    Raises
    ------
    ValueError
        If an argument is not finite, has the wrong shape, if two nodes are
        equal, or if a weight is zero.

    Notes
    -----
    With ``q_j(t) = w_j / (t - x_j)`` the interpolant is ([1]_, the "true" barycentric formula)

    .. math::

        p(t) = \\frac{\\sum_j q_j(t) f_j}{\\sum_j q_j(t)} .

    Any common factor of the weights cancels. Higham [2]_ proves the formula
    forward stable for nodes with a small Lebesgue constant (Chebyshev
    points) and ``t`` inside the interval; for equispaced nodes of high
    degree, accuracy is lost in proportion to the conditioning.

    *Extrapolation.* Outside ``[min(nodes), max(nodes)]`` the second formula
    is the wrong tool: its denominator ``sum_j q_j(t)`` cancels (it equals
    ``1 / l(t)`` with ``l(t) = prod_j (t - x_j)``), so far from the nodes it
    loses about ``n log10(|t| / (b - a))`` digits and overflows to NaN or
    infinity where the value is finite. There, when the weights are the
    polynomial's (the default, or given weights within a relative ``1e-8`` of
    them up to a common factor), the interpolant is computed by

    * the first (modified Lagrange) form ``p(t) = sum_j l_j(t) f_j`` with
      ``l_j(t) = w_j prod_{k != j} (t - x_k)``, the unscaled weights and every
      product carried as mantissa and separate exponent, so nothing overflows
      before the result itself does. Higham [2]_ shows it backward stable:
      the computed value is exact for data perturbed by at most
      ``(5n + 5) u`` relatively (``u = 2**-53``), hence its error is at most
      ``B(t) = (5n + 5) u sum_j |l_j(t) f_j|``;
    * the Newton form (divided differences over ascending nodes, nested
      evaluation with the same mantissa/exponent scaling), often far more
      accurate far away and exact for data of low degree (a constant stays
      that constant at ``t = 1e300``), but without such a guarantee.

    The Newton value is returned when it lies within ``B(t)`` of the first
    form's, otherwise the first form's; either way the error is at most
    ``2 B(t)`` (to first order in ``u``). ``B(t) / |p(t)|`` is the condition
    number of the value with respect to the data times ``(5n + 5) u``: far
    extrapolation of high-degree interpolants is ill-conditioned whatever the
    algorithm. With other weights (a barycentric rational interpolant) the
    second formula is used everywhere, as it defines that interpolant.

    ``t`` is processed in chunks of at most ``2**12`` points and ``2**19``
    point-node pairs, so the temporary matrix ``q`` never exceeds 4 MiB
    whatever the size of ``t`` (SciPy's ``BarycentricInterpolator`` forms it
    for all points at once). Numerators and denominator come from one
    matrix product ``q @ [values, 1]``.

    A row whose result is not finite has ``t`` on a node (``q_j`` infinite)
    or so close to one that ``q_j`` overflowed. Such rows are recomputed
    after multiplying every ``q_j`` by the distance to the nearest node,
    which bounds all of them by ``|w_j|``; exact hits then return the data
    value itself. Thus ``t = x_j`` gives ``values[j]`` exactly and
    ``t = nextafter(x_j, +-inf)`` gives a finite value within rounding of
    ``values[j]``. A single node gives the constant ``values[0]`` exactly.

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`
    .. [2] N. J. Higham, "The numerical stability of barycentric Lagrange
       interpolation", IMA Journal of Numerical Analysis 24(4), 547-556,
       2004. :doi:`10.1093/imanum/24.4.547`
    .. [3] N. J. Higham, "Accuracy and Stability of Numerical Algorithms",
       2nd ed., SIAM, 2002, Section 5.3 (the Newton form).

    Examples
    --------
    Interpolate ``x**2`` in three nodes, then Runge's function in Chebyshev
    points:

    >>> import numpy as np
    >>> from reference import (barycentric_interpolate,
    ...     chebyshev_nodes, chebyshev_weights)
    >>> print(barycentric_interpolate([-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], 0.5))
    0.25
    >>> x = chebyshev_nodes(64)
    >>> t = np.linspace(-1, 1, 1001)
    >>> p = barycentric_interpolate(x, 1 / (1 + 16 * x**2), t, chebyshev_weights(64))
    >>> bool(np.max(np.abs(p - 1 / (1 + 16 * t**2))) < 1e-5)
    True

    Far outside the nodes the value stays finite and accurate:

    >>> print(barycentric_interpolate([0.0, 1.0], [3.0, 3.0], 1e300))
    3.0
    >>> print(barycentric_interpolate([-1.0, 0.0, 1.0], [1.0, 0.0, 1.0], 1e17))
    1e+34
    """
    x, origin = _as_nodes(nodes)
    y = _as_values(values, x.size)
    tt = shift_parameter(t, "t", origin)
    w = _as_weights(weights, x)
    if x.size == 1:  # the constant interpolant, exactly
        result = np.broadcast_to(y[0], tt.shape + y.shape[1:]).reshape(
            tt.shape + np.shape(values)[1:]
        ).copy()
        return result[()] if result.ndim == 0 else result
    y1 = np.concatenate([y, np.ones((x.size, 1))], axis=1)
    flat = tt.ravel()
    out = np.empty((flat.size, y.shape[1]))
    second = None  # rows for the second formula: all of them, or these indices
    outside = (flat < x.min()) | (flat > x.max())
    if outside.any() and (weights is None or _are_polynomial_weights(x, w)):
        out[outside] = _extrapolate(x, y, flat[outside])
        second = np.flatnonzero(~outside)
    del outside
    pieces = list(_chunks(flat.size if second is None else second.size, x.size))
    if pieces:
        buf = np.empty((pieces[0].stop - pieces[0].start, x.size))
        for piece in pieces:
            rows = piece if second is None else second[piece]
            out[rows] = _interpolate_chunk(x, w, y1, flat[rows], buf)
    result = out.reshape(tt.shape + np.shape(values)[1:])
    return result[()] if result.ndim == 0 else result


# --------------------------------------------------------------------------
# Lebesgue constant
# --------------------------------------------------------------------------


def _lebesgue_function(
    x: NDArray[np.float64], w: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``sum_j |l_j(t)| = sum_j |q_j| / |sum_j q_j|`` at the points ``t``."""
    out = np.empty(t.size)
    for piece in _chunks(t.size, x.size):
        tc = t[piece]
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            q = w / (tc[:, None] - x[None, :])
            lam = np.abs(q).sum(axis=1) / np.abs(q.sum(axis=1))
        bad = np.flatnonzero(~np.isfinite(lam))
        if bad.size:
            terms, _ = _rescaled_terms(x, w, tc[bad])
            lam[bad] = np.abs(terms).sum(axis=1) / np.abs(terms.sum(axis=1))
        out[piece] = lam
    return out


def _golden_maximise(
    f: Any, lo: NDArray[np.float64], hi: NDArray[np.float64], steps: int
) -> NDArray[np.float64]:
    """Golden-section search for a maximum on each bracket ``[lo_i, hi_i]`` at once."""
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = lo.copy(), hi.copy()
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = f(c), f(d)
    best = np.maximum(fc, fd)
    for _ in range(steps):
        left = fc >= fd  # the maximum lies in [a, d]
        b = np.where(left, d, b)
        a = np.where(left, a, c)
        c_new = np.where(left, b - ratio * (b - a), d)
        d_new = np.where(left, c, a + ratio * (b - a))
        probe = np.where(left, c_new, d_new)
        fp = f(probe)
        fc_new = np.where(left, fp, fd)
        fd_new = np.where(left, fc, fp)
        c, d, fc, fd = c_new, d_new, fc_new, fd_new
        best = np.maximum(best, fp)
    return best


def lebesgue_constant(nodes: ArrayLike, weights: ArrayLike | None = None) -> float:
    """Return the Lebesgue constant of interpolation in ``nodes``.

    Parameters
    ----------
    nodes : array_like of shape (n + 1,)
        Pairwise distinct, finite nodes, in any order.
    weights : array_like of shape (n + 1,), optional
        Barycentric weights (any common scale, non-zero). Default:
        ``barycentric_weights(nodes)``, the polynomial interpolant. Other
        weights give the Lebesgue constant of that barycentric rational
        interpolant.

    Returns
    -------
    Lambda : float
        ``max_{x in [a, b]} sum_j |l_j(x)|`` with ``[a, b] = [min(nodes),
        max(nodes)]``; ``1.0`` for a single node.

    Raises
    ------
    ValueError
        For invalid ``nodes`` or ``weights`` (as in
        :func:`barycentric_interpolate`).

    Notes
    -----
    ``Lambda`` bounds the amplification of data errors,
    ``||p - p*|| <= (1 + Lambda) ||f - p*||`` for the best approximation
    ``p*``. The Lebesgue function is evaluated in barycentric form,

    .. math::

        \\lambda(x) = \\sum_j |\\ell_j(x)|
        = \\frac{\\sum_j |w_j / (x - x_j)|}{|\\sum_j w_j / (x - x_j)|},

    first on a grid of at least ``4096`` interior points in total and at
    least ``16`` per gap between consecutive nodes (``lambda = 1`` at the
    nodes themselves); then, in every gap, the best grid point is refined by
    48 golden-section steps on its two neighbouring grid cells.

    Accuracy. Discretisation: the refinement converges to the local maximum
    of the gap whenever ``lambda`` is unimodal on the bracket, which the
    grid resolution makes so in practice; the result is then limited by
    rounding only, and it is never above the true value by more than
    rounding. Rounding: the denominator is a sum whose condition number is
    ``lambda(x)`` itself, so the relative error is bounded by about
    ``(n + 1) eps Lambda``: full accuracy for Chebyshev points, while for
    equispaced nodes the error measured against 40-digit arithmetic is
    ``2e-12`` at ``n = 20``, ``7e-8`` at ``n = 40`` and ``1e-6`` at
    ``n = 50``; the result is meaningless once ``Lambda`` nears ``1 / eps``
    (equispaced ``n`` above about 55).

    Known values: for Chebyshev points
    ``Lambda_n <= (2 / pi) log(n + 1) + 1``, for any nodes
    ``Lambda_n >= (2 / pi) log(n + 1) + 0.52``, and for equispaced nodes
    ``Lambda_n ~ 2**(n + 1) / (e n log n)`` (Runge's phenomenon) [2]_.

    References
    ----------
    .. [1] J.-P. Berrut and L. N. Trefethen, "Barycentric Lagrange
       interpolation", SIAM Review 46(3), 501-517, 2004.
       :doi:`10.1137/S0036144502417715`
    .. [2] L. N. Trefethen, "Approximation Theory and Approximation
       Practice", SIAM, 2013, Chapter 15.

    Examples
    --------
    >>> from reference import (lebesgue_constant,
    ...     chebyshev_nodes, equispaced_nodes)
    >>> round(lebesgue_constant(equispaced_nodes(2)), 6)  # exactly 5/4
    1.25
    >>> round(lebesgue_constant(equispaced_nodes(20)))
    10987
    >>> bool(lebesgue_constant(chebyshev_nodes(20)) < 3)
    True
    """
    x, _ = _as_nodes(nodes)
    w = _as_weights(weights, x)
    if x.size == 1:
        return 1.0
    s = np.sort(x)
    per_gap = max(_LEBESGUE_PER_GAP, -(-_LEBESGUE_SAMPLES // (s.size - 1)))
    u = np.arange(per_gap + 2) / (per_gap + 1)  # 0, ..., 1 with the end nodes
    grid = s[:-1, None] + (s[1:] - s[:-1])[:, None] * u[None, :]
    grid[:, -1] = s[1:]
    values = np.ones_like(grid)
    values[:, 1:-1] = _lebesgue_function(x, w, grid[:, 1:-1].ravel()).reshape(
        s.size - 1, per_gap
    )
    k = np.clip(np.argmax(values, axis=1), 1, per_gap)
    rows = np.arange(s.size - 1)
    refined = _golden_maximise(
        lambda p: _lebesgue_function(x, w, p),
        grid[rows, k - 1],
        grid[rows, k + 1],
        _GOLDEN_STEPS,
    )
    return float(max(values.max(), refined.max()))
