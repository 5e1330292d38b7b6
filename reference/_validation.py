"""Input normalisation shared by every public function of :mod:`reference`.

Every public routine calls one of these helpers first and then works on clean
arrays (the pattern of SciPy's ``prepare_input`` in ``interpolate/_cubic.py``).
Messages name the argument, state the rule and show what was received.

What is refused everywhere, rather than silently changed:

* masked arrays (the mask would be ignored);
* complex numbers, even with a zero imaginary part (the maths is real);
* anything that is not a real number (strings, ``None``, objects);
* NaN, infinity, and numbers too large for a double (``10**400``).

Each raises ``ValueError`` (the exception every public function documents)
with a message naming the argument and the rule.

Integers are accepted at any size that a double can hold. The geometric
predicates keep them exact (:func:`as_exact_array`); the numerical routines
work in double precision (:func:`as_finite_array`).
"""

from __future__ import annotations

import math
import numbers
import sys
from fractions import Fraction
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "as_finite_array",
    "as_exact_array",
    "as_point",
    "as_points",
    "as_exact_point",
    "as_exact_points",
    "as_nonnegative_int",
    "as_parameter",
    "check_choice",
    "as_abscissae",
    "shift_parameter",
    "as_chebyshev_kind",
    "as_nodes",
    "as_weights",
]

#: Integers of at most this magnitude are exactly representable as doubles.
_EXACT_INT = 2**53
#: Largest finite double.
_MAX = sys.float_info.max


def _parse(value: Any, name: str) -> NDArray[Any]:
    """``value`` as an ndarray of a real numeric dtype, or of ``object`` numbers.

    Refuses masked arrays, complex values and non-numbers; does not yet check
    finiteness.
    """
    if isinstance(value, np.ma.MaskedArray):
        raise ValueError(
            f"`{name}` must be a plain array, not a masked array (its mask would be "
            "ignored); pass `value.filled(...)` or `value.compressed()`."
        )
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise ValueError(
            f"`{name}` must be an array of real numbers; got {type(value).__name__}."
        ) from exc
    kind = arr.dtype.kind
    if kind == "c":
        raise ValueError(
            f"`{name}` must contain real values; got complex values (dtype {arr.dtype}). "
            "Pass the real part explicitly if that is what you mean."
        )
    if kind in "biuf":
        return arr
    if kind == "O":
        for v in arr.reshape(-1):
            if isinstance(v, (complex, np.complexfloating)):
                raise ValueError(
                    f"`{name}` must contain real values; got the complex value {v!r}."
                )
            if not isinstance(v, numbers.Real):
                raise ValueError(
                    f"`{name}` must be an array of real numbers; got an element of "
                    f"type {type(v).__name__}."
                )
        return arr
    raise ValueError(
        f"`{name}` must be an array of real numbers; got {type(value).__name__} "
        f"of dtype {arr.dtype}."
    )


def _too_large(name: str, v: Any) -> ValueError:
    try:
        size = f"about 1e{int(math.log10(abs(v)))}"
    except (TypeError, ValueError, OverflowError):  # pragma: no cover - defensive
        size = repr(v)
    return ValueError(
        f"`{name}` must hold values that fit in a double (magnitude at most "
        f"{_MAX:.4g}); got {size}."
    )


def _not_finite(name: str) -> ValueError:
    return ValueError(f"`{name}` must contain only finite values (no NaN or inf).")


def _float_exact(v: Any) -> bool:
    """True when the real number ``v`` equals a double exactly."""
    if isinstance(v, (float, np.floating)):
        return bool(np.isfinite(v)) and (
            not isinstance(v, np.longdouble) or float(v) == v
        )
    if isinstance(v, numbers.Integral):
        return abs(int(v)) <= _EXACT_INT
    try:
        return Fraction(float(v)) == v
    except (OverflowError, ValueError):
        return False


def _exact_number(v: Any, name: str) -> int | Fraction:
    """``v`` as an exact Python ``int`` or ``Fraction``, checked to fit in a double."""
    if isinstance(v, numbers.Integral):
        out: int | Fraction = int(v)
    elif isinstance(v, (float, np.floating)):
        if not np.isfinite(v):
            raise _not_finite(name)
        x = Fraction(v) if not isinstance(v, np.longdouble) else Fraction(*v.as_integer_ratio())
        out = x.numerator if x.denominator == 1 else x
    else:
        out = Fraction(v)
    if abs(out) > _MAX:
        raise _too_large(name, out)
    return out


def _from_objects(arr: NDArray[Any], name: str) -> NDArray[Any]:
    """Object array of real numbers -> float64 when every value is a double, else
    an exact object array of ``int``/``Fraction``."""
    flat = arr.reshape(-1)
    if all(_float_exact(v) for v in flat):
        return arr.astype(np.float64)
    out = np.empty(arr.shape, dtype=object)
    out_flat = out.reshape(-1)
    for i, v in enumerate(flat):
        out_flat[i] = _exact_number(v, name)
    return out


def _check_ndim(arr: NDArray[Any], name: str, ndim: int | None) -> None:
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(
            f"`{name}` must be {ndim}-dimensional; got an array of shape {arr.shape}."
        )


def as_exact_array(value: ArrayLike, name: str, *, ndim: int | None = None) -> NDArray[Any]:
    """Return ``value`` exactly: a float64 array, or an object array of ints/Fractions.

    Float64 is returned whenever it represents every value exactly (all
    doubles, integers up to ``2**53``); otherwise (larger integers, e.g. int64
    near ``2**62``, Python ints, or such integers mixed with floats) the
    values are kept as Python ``int`` and :class:`fractions.Fraction`. Every
    value must fit in a double; NaN and infinity are refused.
    """
    arr = _parse(value, name)
    _check_ndim(arr, name, ndim)
    kind = arr.dtype.kind
    if kind == "O":
        return _from_objects(arr, name)
    if kind in "iu":
        if arr.size == 0 or (int(arr.max()) <= _EXACT_INT and int(arr.min()) >= -_EXACT_INT):
            return arr.astype(np.float64)
        return arr.astype(object)  # Python ints; every int64/uint64 fits in a double
    if kind == "f" and arr.size and not isinstance(value, np.ndarray):
        # A list such as [2**53 + 1, 0.5] becomes float64 with the integer
        # rounded; read it again element by element.
        with np.errstate(invalid="ignore"):
            big = np.nanmax(np.abs(arr.astype(np.float64))) >= _EXACT_INT
        if big:
            obj = np.asarray(value, dtype=object)
            if obj.shape == arr.shape:
                return _from_objects(obj, name)
    if arr.dtype == np.longdouble and arr.dtype != np.float64:
        return _from_objects(arr.astype(object), name)
    out = arr.astype(np.float64, copy=False)
    if not np.all(np.isfinite(out)):
        raise _not_finite(name)
    return out


def as_finite_array(value: ArrayLike, name: str, *, ndim: int | None = None) -> NDArray[np.float64]:
    """Return ``value`` as a finite float64 array (integers correctly rounded).

    Raises ``ValueError`` naming ``name`` for masked or complex input, when
    the value is not an array of real numbers, has the wrong number of
    dimensions, holds NaN or infinity, or a number too large for a double.
    """
    arr = _parse(value, name)
    _check_ndim(arr, name, ndim)
    if arr.dtype.kind == "O":
        arr = _from_objects(arr, name)
    with np.errstate(over="ignore"):
        try:
            out = arr.astype(np.float64, copy=False)
        except OverflowError:  # pragma: no cover - caught by _from_objects
            raise _too_large(name, max(abs(v) for v in arr.reshape(-1))) from None
    if not np.all(np.isfinite(out)):
        if arr.dtype.kind == "O" or (arr.dtype.kind == "f" and np.all(np.isfinite(arr))):
            big = max(abs(v) for v in arr.reshape(-1).tolist())
            raise _too_large(name, big)
        raise _not_finite(name)
    return out


def _check_points_shape(
    arr: NDArray[Any], name: str, dim: int | None, min_points: int
) -> None:
    if arr.ndim != 2 or (dim is not None and arr.shape[1] != dim):
        want = f"(n, {dim})" if dim is not None else "(n, d)"
        raise ValueError(f"`{name}` must have shape {want}; got {arr.shape}.")
    if arr.shape[0] < min_points:
        raise ValueError(
            f"`{name}` must hold at least {min_points} point(s); got {arr.shape[0]}."
        )


def as_points(
    value: ArrayLike, name: str = "points", *, dim: int | None = 2, min_points: int = 1
) -> NDArray[np.float64]:
    """Return ``value`` as a finite ``(n, dim)`` float array with ``n >= min_points``."""
    arr = as_finite_array(value, name)
    _check_points_shape(arr, name, dim, min_points)
    return arr


def as_exact_points(
    value: ArrayLike, name: str = "points", *, dim: int | None = 2, min_points: int = 1
) -> tuple[NDArray[Any], NDArray[np.float64]]:
    """Return ``(exact, approx)`` for an ``(n, dim)`` point set.

    ``exact`` is :func:`as_exact_array` of ``value``. ``approx`` is ``exact``
    itself when that is float64; for exact objects it is the correctly
    rounded float64 value of ``exact - origin``, with ``origin`` the integer
    vector of the columns' floors of their minima, so that its rounding error
    is relative to the spread of the points rather than to their magnitude
    (use it only where a translation does not matter: guesses, orderings,
    filters with a margin).
    """
    exact = as_exact_array(value, name)
    _check_points_shape(exact, name, dim, min_points)
    if exact.dtype != object:
        return exact, exact
    if exact.shape[0] == 0:
        return exact, exact.astype(np.float64)
    arr = np.asarray(value)
    if arr.dtype.kind in "iu":
        # Vectorised: a - min(a) lies in [0, 2**64), exact in uint64 arithmetic
        # (which wraps modulo 2**64), then correctly rounded to double.
        low = arr.min(axis=0)
        diff = arr.astype(np.uint64) - low.astype(np.uint64)
        return exact, diff.astype(np.float64)
    origin = [math.floor(min(column)) for column in exact.T.tolist()]
    shifted = [[float(v - o) for v, o in zip(row, origin)] for row in exact.tolist()]
    return exact, np.array(shifted, dtype=np.float64).reshape(exact.shape)


def as_point(value: ArrayLike, name: str, *, dim: int = 2) -> NDArray[np.float64]:
    """Return ``value`` as a finite point of shape ``(dim,)``."""
    arr = as_finite_array(value, name)
    if arr.shape != (dim,):
        raise ValueError(f"`{name}` must be a point of shape ({dim},); got {arr.shape}.")
    return arr


def as_exact_point(value: ArrayLike, name: str, *, dim: int = 2) -> NDArray[Any]:
    """Return ``value`` as a point of shape ``(dim,)``, exactly (see :func:`as_exact_array`)."""
    arr = as_exact_array(value, name)
    if arr.shape != (dim,):
        raise ValueError(f"`{name}` must be a point of shape ({dim},); got {arr.shape}.")
    return arr


def as_nonnegative_int(value: Any, name: str, *, minimum: int = 0) -> int:
    """Return ``value`` as a Python ``int`` that is at least ``minimum``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"`{name}` must be an integer; got {value!r}.")
    if value < minimum:
        raise ValueError(f"`{name}` must be >= {minimum}; got {value}.")
    return int(value)


def as_parameter(
    value: ArrayLike, name: str = "t", *, lo: float | None = None, hi: float | None = None
) -> tuple[NDArray[np.float64], bool]:
    """Return ``(array, was_scalar)`` for a scalar-or-array evaluation parameter.

    When ``lo``/``hi`` are given, every value must lie in ``[lo, hi]``.
    """
    arr = as_finite_array(value, name)
    if arr.ndim > 1:
        raise ValueError(f"`{name}` must be a scalar or 1-D array; got shape {arr.shape}.")
    if (lo is not None and np.any(arr < lo)) or (hi is not None and np.any(arr > hi)):
        raise ValueError(f"`{name}` must lie in [{lo}, {hi}].")
    return np.atleast_1d(arr), arr.ndim == 0


def check_choice(value: Any, name: str, choices: tuple[str, ...]) -> str:
    """Return ``value`` when it is one of ``choices``, else raise ``ValueError``."""
    if value not in choices:
        options = ", ".join(repr(c) for c in choices)
        raise ValueError(f"`{name}` must be one of {options}; got {value!r}.")
    return value


def as_abscissae(
    value: ArrayLike, name: str, *, ndim: int | None = 1
) -> tuple[NDArray[np.float64], int]:
    """Return ``(values - origin, origin)``: abscissae as doubles, shifted when needed.

    Doubles, and integers up to ``2**53``, are returned as they are with
    ``origin = 0``. Larger integers (int64 near ``2**62``, Python ints) would
    round, and distinct ones could become equal; they are shifted by the
    integer ``origin = min(values)`` first, exactly, so that nearby integers
    stay distinct (``[2**62, 2**62 + 1]`` becomes ``[0.0, 1.0]``). Callers
    that evaluate at points ``t`` shift them with :func:`shift_parameter`.
    Interpolation is translation invariant, so the results do not change.
    """
    exact = as_exact_array(value, name, ndim=ndim)
    if exact.dtype != object or exact.size == 0:
        return exact, 0
    origin = min(exact.reshape(-1).tolist())
    origin = int(origin) if not isinstance(origin, Fraction) else int(math.floor(origin))
    shifted = np.array([float(v - origin) for v in exact.reshape(-1).tolist()])
    return shifted.reshape(exact.shape), origin


def shift_parameter(value: ArrayLike, name: str, origin: int) -> NDArray[np.float64]:
    """``value - origin`` as finite doubles, for the ``origin`` of :func:`as_abscissae`.

    With ``origin == 0`` this is :func:`as_finite_array`. Otherwise integers
    are shifted exactly and doubles with an error-free transformation
    (Knuth's TwoSum), so the result is within one rounding of the exact
    difference.
    """
    if origin == 0:
        return as_finite_array(value, name)
    exact = as_exact_array(value, name)
    if exact.dtype == object:
        flat = [float(v - origin) for v in exact.reshape(-1).tolist()]
        return np.array(flat, dtype=np.float64).reshape(exact.shape)
    hi = float(origin)
    lo = float(origin - int(hi))
    s = exact - hi
    # TwoSum of exact and -hi: err is the rounding error of s, exactly.
    bb = s - exact
    err = (exact - (s - bb)) + (-hi - bb)
    return s + (err - lo)


def as_chebyshev_kind(kind: Any) -> int:
    """Return ``kind`` when it is 1 or 2, the two kinds of Chebyshev points."""
    if isinstance(kind, bool) or not isinstance(kind, numbers.Integral) or kind not in (1, 2):
        raise ValueError(
            f"`kind` must be 1 (Chebyshev points of the first kind, the roots) or "
            f"2 (of the second kind, the extrema); got {kind!r}."
        )
    return int(kind)


def as_nodes(nodes: ArrayLike) -> tuple[NDArray[np.float64], int]:
    """Finite, non-empty, 1-D, pairwise distinct nodes (any order), and their origin.

    Integers beyond ``2**53`` are shifted by an integer origin first (see
    :func:`as_abscissae`), so distinct integers stay distinct; the interpolant
    is translation invariant.
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


def as_weights(weights: ArrayLike, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Validated weights, rescaled by a power of two so that max |w| is in [0.5, 1).

    The rescaling is exact (barring weights spanning more than the whole
    exponent range) and harmless, since the formula ignores a common factor;
    it keeps ``w / (t - x_j)`` away from overflow for user weights such as
    the lecture's raw binomial coefficients. The nodes ``x`` are those
    :func:`as_nodes` returned; without weights, callers compute the
    polynomial's (``reference._weights.barycentric_weights``) instead.
    """
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
