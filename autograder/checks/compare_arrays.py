"""Staged comparisons for check authors: type, then shape, then values, then where.

Each helper raises :class:`~autograder.errors.CheckFailure` with a message a
student can act on ("expected X, got Y, at Z"), computed from the data and
never from the check's source.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from autograder.errors import CheckFailure

__all__ = [
    "CheckFailure",
    "describe",
    "expect_array",
    "expect_close",
    "expect_equal",
    "expect_indices",
    "expect_int",
    "expect_number",
    "same_cycle",
    "is_rotation_reversed",
]

_KIND_WORDS = {"b": "booleans", "i": "integers", "u": "integers", "f": "real numbers",
               "c": "complex numbers"}


def describe(value: Any) -> str:
    """A short, safe description of a decoded value ("a list of 5 items", "an array (3, 2)")."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    if isinstance(value, (list, tuple)):
        return f"a {type(value).__name__} of {len(value)} item(s)"
    if value is None:
        return "None (did you forget `return`?)"
    return f"a {type(value).__name__} ({_short(value)})"


def _short(value: Any, width: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def expect_array(got: Any, *, shape: Sequence[int | None] | None = None,
                 dtype_kind: str = "biuf", name: str = "the result",
                 hint: str = "") -> NDArray[Any]:
    """Return ``got`` as an array, checking its element kind and shape.

    ``shape`` may hold ``None`` for any length in that dimension. ``hint``, if
    given, ends every failure message (say what the answer should look like:
    "Return the row numbers of the corners, like [2, 1, 4].").
    """
    def fail(message: str) -> CheckFailure:
        return CheckFailure(f"{message} {hint}" if hint else message)

    if got is None or isinstance(got, (str, bytes, dict)):
        raise fail(f"{name} should be an array-like of {_kinds(dtype_kind)}; got {describe(got)}.")
    try:
        arr = np.asarray(got)
    except (ValueError, TypeError):
        raise fail(f"{name} should be a rectangular array-like; got {describe(got)}.") from None
    if arr.dtype.kind not in dtype_kind:
        raise fail(f"{name} should hold {_kinds(dtype_kind)}; got {describe(got)}.")
    if shape is not None:
        ok = arr.ndim == len(shape) and all(w is None or w == n for w, n in zip(shape, arr.shape))
        if not ok:
            want = "(" + ", ".join("any" if w is None else str(w) for w in shape) + ")"
            raise fail(f"{name} should have shape {want}; got shape {arr.shape}.")
    return arr


def _kinds(dtype_kind: str) -> str:
    words = dict.fromkeys(_KIND_WORDS[k] for k in dtype_kind if k in _KIND_WORDS)
    return " or ".join(words) or "numbers"


def expect_indices(got: Any, n: int, *, shape: Sequence[int | None] | None = None,
                   name: str = "the result", rows: str = "`points`",
                   at: Callable[[tuple[int, ...]], str] | None = None,
                   hint: str = "") -> NDArray[np.int64]:
    """Return ``got`` as an int64 array of row numbers of a table of ``n`` rows.

    Stages: integers of the given ``shape`` (:func:`expect_array`), then every
    index in ``0 .. n - 1``: the first one outside is named with where it is
    (``at(index)``, default its entry in ``got``). ``rows`` names the table
    in the message; ``hint`` ends every failure message.
    """
    arr = expect_array(got, shape=shape, dtype_kind="iu", name=name, hint=hint)
    bad = np.argwhere((arr < 0) | (arr >= n))
    if bad.size:
        where = tuple(int(i) for i in bad[0])
        place = at(where) if at else f"entry {_index(where)}"
        span = f"{n} rows, so indices run from 0 to {n - 1}" if n else "no rows"
        raise CheckFailure(_with_hint(f"{name} holds {int(arr[where])} at {place}, which is "
                                      f"not a row of {rows}: it has {span}.", hint))
    return arr.astype(np.int64)


def expect_int(got: Any, *, name: str = "the result") -> int:
    """Return ``got`` as a Python int (bools and floats with a fraction are refused)."""
    if isinstance(got, np.ndarray) and got.ndim == 0:
        got = got.item()
    if isinstance(got, bool) or not isinstance(got, (int, np.integer, float)):
        raise CheckFailure(f"{name} should be an integer; got {describe(got)}.")
    if isinstance(got, float) and not got.is_integer():
        raise CheckFailure(f"{name} should be an integer; got {got!r}.")
    return int(got)


def expect_number(got: Any, *, name: str = "the result", hint: str = "") -> float:
    """Return ``got`` as a Python float: a real number, or a 0-d array of one.

    For a scalar answer to a scalar input: bools, strings, None and arrays of
    any other shape (even of one value) are refused, with ``hint`` at the end.
    """
    if isinstance(got, np.ndarray) and got.ndim == 0 and got.dtype.kind in "iuf":
        got = got.item()
    if isinstance(got, bool) or not isinstance(got, (int, float, np.integer, np.floating)):
        raise CheckFailure(_with_hint(f"{name} should be a single number; got {describe(got)}.",
                                      hint))
    return float(got)


def expect_close(got: Any, expected: Any, *, rtol: ArrayLike, atol: ArrayLike,
                 name: str = "the result", at: Callable[[tuple[int, ...]], str] | None = None,
                 hint: str = "") -> NDArray[Any]:
    """Check ``got`` against ``expected`` elementwise within ``atol + rtol * |expected|``.

    Stages: type and shape (:func:`expect_array`), then non-finite values (NaN
    exactly where NaN is expected, an infinity exactly where the same infinity
    is expected), then the finite values against the tolerance. Each failure
    names the worst offending entry, what was expected there, what came back,
    how far off it is and how far it may be, and how many entries fail.

    Parameters
    ----------
    rtol, atol : float or array_like
        Tolerances; arrays broadcast against ``expected`` (a tolerance per
        column, per point, ...). Each must be >= 0.
    name : str, optional
        What was compared, usually the call (``"f(x)"``).
    at : callable, optional
        ``at(index) -> str`` says where an entry is, for the message
        (``lambda i: f"node {i[0]}"``, ``lambda i: f"t = {t[i]}"``); default
        ``"index [i, j]"``.
    hint : str, optional
        Ends every failure message: how to find or fix the mistake.
    """
    want = np.asarray(expected)
    if want.dtype.kind not in "biufc":
        raise TypeError(f"`expected` must hold numbers; got dtype {want.dtype}.")
    rtol_, atol_ = (_tolerance(v, key, want.shape) for v, key in ((rtol, "rtol"), (atol, "atol")))
    arr = expect_array(got, shape=want.shape, dtype_kind="biufc", name=name, hint=hint)
    where_text = at or (lambda where: f"index {_index(where)}")
    kind = complex if "c" in (arr.dtype.kind, want.dtype.kind) else float
    g, w = arr.astype(kind), want.astype(kind)
    _expect_same_non_finite(g, w, name, where_text, hint)
    finite = np.isfinite(w)
    err = np.where(finite, np.abs(g - np.where(finite, w, 0)), 0.0).astype(float)
    bound = atol_ + rtol_ * np.where(finite, np.abs(w), 0.0)
    over = err > bound
    if over.any():
        where = tuple(int(i) for i in np.unravel_index(np.argmax(err - bound), err.shape)) \
            if err.ndim else ()
        raise CheckFailure(_with_hint(
            f"{name} is off at {where_text(where)}: expected {_num(w[where])}, got "
            f"{_num(g[where])} (error {float(err[where]):.2e}, allowed "
            f"{float(bound[where]):.2e}); {int(over.sum())} of {over.size} value(s) are "
            "outside the tolerance.", hint))
    return arr


def _tolerance(value: ArrayLike, key: str, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """A tolerance as a float array broadcast to ``shape``; refused unless finite and >= 0."""
    try:
        tol = np.broadcast_to(np.asarray(value, dtype=float), shape)
    except (TypeError, ValueError):
        raise ValueError(f"`{key}` must be a number or an array that broadcasts to the "
                         f"expected shape {shape}; got {_short(value)}.") from None
    if not np.all(tol >= 0) or not np.all(np.isfinite(tol)):
        raise ValueError(f"`{key}` must be finite and >= 0; got {_short(value)}.")
    return tol


def _with_hint(message: str, hint: str) -> str:
    return f"{message} {hint}" if hint else message


def _num(value: Any) -> str:
    """A number as the shortest text that reads back as the same double (``repr``)."""
    if isinstance(value, (complex, np.complexfloating)):
        return repr(complex(value))
    value = float(value)
    if value.is_integer() and abs(value) < 2.0**53:
        return str(int(value))
    return repr(value)


def _expect_same_non_finite(got: NDArray[Any], want: NDArray[Any], name: str,
                            at: Callable[[tuple[int, ...]], str], hint: str) -> None:
    """Fail at the first index where NaN or an infinity is in one array and not the other."""
    def label(v: Any) -> str:
        return "NaN" if np.isnan(v) else ("+inf" if np.real(v) > 0 or np.imag(v) > 0
                                          else "-inf") if np.isinf(v) else _num(v)

    got_nan, want_nan = np.isnan(got), np.isnan(want)
    got_inf, want_inf = np.isinf(got) & ~got_nan, np.isinf(want) & ~want_nan
    mismatch = (got_nan != want_nan) | (got_inf != want_inf)
    mismatch |= got_inf & want_inf & (got != want)  # +inf against -inf
    if mismatch.any():
        where = tuple(int(i) for i in np.argwhere(mismatch)[0])
        g, w = got[where], want[where]
        count = int(mismatch.sum())
        more = f" ({count} of {mismatch.size} values differ so)" if count > 1 else ""
        raise CheckFailure(_with_hint(f"{name} has {label(g)} at {at(where)} where "
                                      f"{label(w)} was expected{more}.", hint))


def _index(where: tuple[int, ...]) -> str:
    return "[" + ", ".join(map(str, where)) + "]" if where else "(scalar)"


def expect_equal(got: Any, expected: Any, *, name: str = "the result") -> None:
    """Check exact equality of plain values or integer/boolean arrays."""
    if isinstance(expected, np.ndarray) or isinstance(got, np.ndarray):
        want = np.asarray(expected)
        arr = expect_array(got, shape=want.shape, dtype_kind="biuf", name=name)
        diff = arr != want
        if diff.any():
            where = tuple(int(i) for i in np.argwhere(diff)[0])
            raise CheckFailure(f"{name} differs at index {_index(where)}: expected "
                               f"{want[where]!r}, got {arr[where]!r}.")
        return
    if type(got) is bool or type(expected) is bool:
        same = type(got) is type(expected) and got == expected
    else:
        same = got == expected
    if not same:
        raise CheckFailure(f"{name}: expected {_short(expected)}, got {describe(got)}.")


def same_cycle(got: Sequence[int], expected: Sequence[int]) -> bool:
    """Whether ``got`` is ``expected`` read from another starting vertex."""
    g, e = [int(x) for x in got], [int(x) for x in expected]
    if len(g) != len(e):
        return False
    if not e:
        return True
    doubled = e + e
    return any(doubled[k:k + len(g)] == g for k in range(len(e)))


def is_rotation_reversed(got: Sequence[int], expected: Sequence[int]) -> bool:
    """Whether ``got`` is ``expected`` traversed the other way round."""
    return same_cycle(list(got)[::-1], expected)
