"""Input normalisation shared by every public function of :mod:`reference`.

Every public routine calls one of these helpers first and then works on clean
arrays (the pattern of SciPy's ``prepare_input`` in ``interpolate/_cubic.py``).
Messages name the argument, state the rule and show what was received.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "as_finite_array",
    "as_point",
    "as_points",
    "as_nonnegative_int",
    "as_parameter",
    "check_choice",
]


def as_finite_array(
    value: ArrayLike, name: str, *, ndim: int | None = None, dtype: Any = np.float64
) -> NDArray[np.float64]:
    """Return ``value`` as a float array, checking that it is finite.

    Raises ``ValueError`` naming ``name`` when the value cannot be converted,
    has the wrong number of dimensions, or holds NaN or infinity.
    """
    try:
        arr = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"`{name}` must be an array of real numbers; got {type(value).__name__}."
        ) from exc
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(
            f"`{name}` must be {ndim}-dimensional; got an array of shape {arr.shape}."
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must contain only finite values (no NaN or inf).")
    return arr


def as_points(
    value: ArrayLike, name: str = "points", *, dim: int | None = 2, min_points: int = 1
) -> NDArray[np.float64]:
    """Return ``value`` as a finite ``(n, dim)`` float array with ``n >= min_points``."""
    arr = as_finite_array(value, name)
    if arr.ndim != 2 or (dim is not None and arr.shape[1] != dim):
        want = f"(n, {dim})" if dim is not None else "(n, d)"
        raise ValueError(f"`{name}` must have shape {want}; got {arr.shape}.")
    if arr.shape[0] < min_points:
        raise ValueError(
            f"`{name}` must hold at least {min_points} point(s); got {arr.shape[0]}."
        )
    return arr


def as_point(value: ArrayLike, name: str, *, dim: int = 2) -> NDArray[np.float64]:
    """Return ``value`` as a finite point of shape ``(dim,)``."""
    arr = as_finite_array(value, name)
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
