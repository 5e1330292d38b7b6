"""The values that cross the boundary besides plain Python data, and what both sides do with them.

:class:`Unsupported` stands for a value the worker could not encode;
:class:`CallableRef` for a function that stays on the side that sent it;
:data:`SAFE_FUNCTIONS` names the functions the worker may evaluate itself; and
:func:`replace_refs` lets each side turn refs into its own calling objects. They
are plain frozen data: :mod:`autograder.boundary.codec` encodes and decodes them,
and, like the codec, this module imports only the standard library and the
boundary's limits.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

from autograder.boundary.limits import MAX_DEPTH

__all__ = ["Unsupported", "CallableRef", "SAFE_FUNCTIONS", "replace_refs"]


@dataclasses.dataclass(frozen=True, slots=True)
class Unsupported:
    """A value the worker could not encode, as it arrives on the trusted side.

    ``type`` is the qualified type name, ``repr`` a short (reprlib-limited)
    repr, ``reason`` why it could not cross. The proxy turns it into
    :class:`~autograder.errors.UnsupportedValue`.
    """

    type: str
    repr: str
    reason: str = ""


#: Functions a check may let the worker evaluate itself, by name (pure, elementwise numpy
#: ufuncs: no state, no I/O, no callbacks). The worker resolves each name in numpy itself.
SAFE_FUNCTIONS = frozenset(f"numpy.{name}" for name in (
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "sinh", "cosh", "tanh", "arcsinh",
    "arccosh", "arctanh", "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "sqrt",
    "cbrt", "square", "absolute", "abs", "sign", "reciprocal", "floor", "ceil", "rint",
    "negative", "positive", "deg2rad", "rad2deg",
))


@dataclasses.dataclass(frozen=True, slots=True)
class CallableRef:
    """A function that stays on the side that sent it, as plain data.

    ``id`` identifies it to its owner (the grader's callback registry, or the
    worker's table of returned functions), ``name`` is for messages only and
    ``safe`` (a name in :data:`SAFE_FUNCTIONS`, or ``""``) lets the worker
    evaluate the function itself.
    """

    id: str
    name: str = "f"
    safe: str = ""


def replace_refs(value: object, make: Callable[[CallableRef], object], _depth: int = 0) -> object:
    """``value`` with every :class:`CallableRef` in it replaced by ``make(ref)``.

    Walks only the exact containers :func:`~autograder.boundary.codec.decode` builds
    (list, tuple, dict); containers holding no ref are returned as they are, not
    copied.
    """
    t = type(value)
    if t is CallableRef:
        return make(value)  # type: ignore[arg-type]
    if _depth > MAX_DEPTH or t not in (list, tuple, dict):
        return value
    if t is dict:
        items = value.items()  # type: ignore[attr-defined]
        new = {k: replace_refs(v, make, _depth + 1) for k, v in items}
        return value if all(new[k] is v for k, v in items) else new
    new_items = [replace_refs(v, make, _depth + 1) for v in value]  # type: ignore[attr-defined]
    if all(a is b for a, b in zip(new_items, value)):  # type: ignore[call-overload]
        return value
    return new_items if t is list else tuple(new_items)
