"""Interpolation nodes on ``[-1, 1]``: the equispaced and the Chebyshev families.

Model solutions for the interpolation part of the geometry-and-interpolation
lecture (its ``EquispacedNodes`` demo and the Runge phenomenon it shows).

Public functions
----------------
equispaced_nodes, chebyshev_nodes
    ``n + 1`` nodes on ``[-1, 1]`` in ascending order.

Their barycentric weights in closed form are in :mod:`reference._weights`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from reference._validation import as_chebyshev_kind, as_nonnegative_int

__all__ = [
    "equispaced_nodes",
    "chebyshev_nodes",
]


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
    n = as_nonnegative_int(n, "n", minimum=1)
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
    n = as_nonnegative_int(n, "n", minimum=1)
    kind = as_chebyshev_kind(kind)
    if kind == 1:
        return _odd_sine_nodes(n, 2 * n + 2)
    x = _odd_sine_nodes(n, 2 * n)
    x[0], x[-1] = -1.0, 1.0
    return x

