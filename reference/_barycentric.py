"""Evaluation of the polynomial interpolant in barycentric form.

Model solutions for the interpolation part of the geometry-and-interpolation
lecture (its ``LagrangeInterp1D`` demo and the Runge phenomenon it shows).

Public functions
----------------
barycentric_interpolate
    The second (true) barycentric formula, vectorised and evaluated in chunks;
    outside the nodes the first form and the Newton form (see its Notes).

The nodes and weights it takes come from :mod:`reference._nodes` and
:mod:`reference._weights`. The evaluation in chunks (:func:`_chunks`) and the
rescaled terms next to a node (:func:`_rescaled_terms`) also serve the
Lebesgue function of :mod:`reference._lebesgue`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from reference._validation import as_finite_array, as_nodes, as_weights, shift_parameter
from reference._weights import barycentric_weights

__all__ = [
    "barycentric_interpolate",
]

#: Unit roundoff of IEEE binary64.
_UNIT_ROUNDOFF = 2.0**-53
#: Evaluation points per chunk (at most); bounds the temporary matrix. Chunks
#: of 2**11 to 2**14 points run equally fast (within 15 %); smaller ones stay in
#: cache.
_CHUNK_POINTS = 2**12
#: Elements of the (points x nodes) temporary per chunk (at most): 4 MiB.
_CHUNK_ELEMENTS = 2**19


# --------------------------------------------------------------------------
# Validation helper private to this module
# --------------------------------------------------------------------------


def _as_values(values: ArrayLike, n_nodes: int) -> NDArray[np.float64]:
    """``values`` as an ``(n_nodes, d)`` array (``d = 1`` for scalar data)."""
    y = as_finite_array(values, "values")
    if y.ndim not in (1, 2) or y.shape[0] != n_nodes:
        raise ValueError(
            f"`values` must have shape ({n_nodes},) or ({n_nodes}, d), one row per "
            f"node; got {y.shape}."
        )
    return y.reshape(n_nodes, -1)


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
    x, origin = as_nodes(nodes)
    y = _as_values(values, x.size)
    tt = shift_parameter(t, "t", origin)
    w = barycentric_weights(x) if weights is None else as_weights(weights, x)
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
