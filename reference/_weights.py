"""Barycentric weights: closed forms for the node families, the product formula for any nodes.

Model solutions for the interpolation part of the geometry-and-interpolation
lecture (its ``EquispacedBarWeights`` demo).

Public functions
----------------
equispaced_weights, chebyshev_weights, barycentric_weights
    Barycentric weights, for the two node families of :mod:`reference._nodes`
    in closed form and for any distinct nodes by the product formula.

Conventions shared by every function here: weights have an arbitrary common
scale (the barycentric formula does not see it); the weights this module
computes are scaled so that ``max |w| == 1`` and the weight of the leftmost
node is positive, so for ascending nodes the signs are ``(-1)**j``. Weights
whose exact value would fall below the smallest normal double
(``sys.float_info.min``, about ``2.2e-308``) are returned as that value with
the right sign, so that every weight is finite, non-zero and normal.
"""

from __future__ import annotations

import sys

import numpy as np
from numpy.typing import ArrayLike, NDArray

from reference._validation import as_chebyshev_kind, as_nodes, as_nonnegative_int

__all__ = [
    "equispaced_weights",
    "chebyshev_weights",
    "barycentric_weights",
]

#: Smallest positive normal double: the floor for the magnitude of a weight.
_TINY = sys.float_info.min


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
    n = as_nonnegative_int(n, "n", minimum=1)
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
    n = as_nonnegative_int(n, "n", minimum=1)
    kind = as_chebyshev_kind(kind)
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
    x, _ = as_nodes(nodes)
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

