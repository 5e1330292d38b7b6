"""Plain-data encoding and framing at the boundary between grader and worker.

This module is imported by both sides: the trusted grader and the untrusted
worker that runs student code. It therefore imports only the standard library,
numpy and :mod:`autograder.errors`, and it never imports :mod:`pickle`, never
calls ``eval``, and never calls a constructor chosen by the data.

Why hand-written
----------------
``pickle`` (and ``dill``, ``cloudpickle``) execute code while loading: a value
returned by a student would run code in the grader. JSON alone is safe but has
no arrays, no tuples, no bytes and no NaN. numpy's ``.npy`` format with
``allow_pickle=False`` is safe for one array but not for nested plain data. So
values cross as a small JSON tree with tagged nodes, and array and byte
payloads travel beside it as raw buffers.

Value tree
----------
Plain JSON (null, bool, int, finite float, str, list, dict with str keys and
no ``"$t"`` key) stands for itself. Tagged nodes (``{"$t": tag, ...}``, exact
key sets) stand for everything else:

``{"$t": "float", "v": "nan" | "inf" | "-inf"}``
    a non-finite float (untagged NaN or Infinity is rejected).
``{"$t": "int", "hex": "-0x1f..."}``
    an int of more than 1024 bits (JSON numbers stay short; at most about
    10 000 decimal digits).
``{"$t": "complex", "re": f, "im": f}``
    a complex number; ``f`` is a float or a float tag.
``{"$t": "tuple", "items": [...]}``
    a tuple.
``{"$t": "dict", "items": [[key, value], ...]}``
    a dict whose keys include ``"$t"`` (keys are always str).
``{"$t": "nd", "dtype": "<f8", "shape": [3, 2], "buf": i}``
    a numpy array of kind ``b i u f c``, C-order bytes in buffer ``i``;
    decoded to a fresh, writeable, base-class ``ndarray``.
``{"$t": "bytes", "buf": i}``
    bytes in buffer ``i``.
``{"$t": "figure", "axes": [...], "png": <bytes>, ...}``
    matplotlib figure data made by the worker's figure encoder; decoded to a
    plain dict that keeps ``"$t": "figure"``, so it equals what the same figure
    data gives when sent as an ordinary (escaped) dict.
``{"$t": "unsupported", "type": str, "repr": str, "reason": str}``
    a value that could not be encoded; decoded to :class:`Unsupported`.
``{"$t": "fn", "id": str, "name": str, "safe": str}``
    a reference to a function that stays on the side that sent it (``safe``
    optional): a function a check passes to student code, or one the student
    returns. Decoded to :class:`CallableRef`, plain data; each side turns refs
    into its own calling objects (:mod:`autograder.engine.callbacks` on the trusted
    side, :mod:`autograder.worker.loop` in the worker), so no function's
    code ever crosses. ``safe`` names a function of :data:`SAFE_FUNCTIONS`
    that the worker may evaluate itself.

Every buffer must be referenced exactly once. Depth counts nested containers
(list, tuple, dict, figure); items count every value node.

Trees compose: a plain dict with str keys (no ``"$t"``) whose values are trees
is a tree, so the worker can wrap the tree from :func:`encode_result` in a
JSON envelope, e.g. ``{"status": "ok", "value": tree}``, and send it with
:func:`send_frame`. :func:`encode_result` leaves room for such an envelope in
its default limits.

Frame
-----
``>I`` length of the header, the UTF-8 (in fact ASCII) JSON header
``{"v": tree, "bufs": [len0, len1, ...]}``, then for each buffer its ``>Q``
length and its bytes. The lengths are in the header *and* before each buffer:
the header copy lets the receiver check the frame's total size against
``max_bytes`` before reading any payload; the prefixes must agree with it.

Errors on receiving: :class:`~autograder.errors.ProtocolError` for a
malformed or oversized frame, :class:`EOFError` when the peer closed the
connection (before or inside a frame), :class:`TimeoutError` when ``timeout``
ran out. After any of these the stream is out of step: close the connection.
"""

from __future__ import annotations

import builtins
import collections
import dataclasses
import json
import math
import re
import reprlib
import socket
import struct
import time
from collections.abc import Callable, Sequence, Set
from typing import Any

import numpy as np

from autograder.errors import ProtocolError

__all__ = [
    "ProtocolError",
    "MAX_FRAME_BYTES",
    "MAX_DEPTH",
    "MAX_ITEMS",
    "MAX_STR_CHARS",
    "MAX_INT_DIGITS",
    "MAX_NDIM",
    "Unsupported",
    "CallableRef",
    "SAFE_FUNCTIONS",
    "replace_refs",
    "encode",
    "encode_result",
    "decode",
    "send_frame",
    "recv_frame",
    "send_message",
    "recv_message",
]

#: Largest frame (length prefix, header, buffers and their prefixes) in bytes.
MAX_FRAME_BYTES = 64 * 2**20
#: Deepest nesting of containers (list, tuple, dict, figure) in a value.
MAX_DEPTH = 32
#: Most value nodes in one tree.
MAX_ITEMS = 1_000_000
#: Longest str (values, dict keys) in characters.
MAX_STR_CHARS = 1_000_000
#: Largest int, in decimal digits (approximately: the check is on bits).
MAX_INT_DIGITS = 10_000
#: Most dimensions of an array.
MAX_NDIM = 32

#: Room left by :func:`encode_result` for the message envelope around a value.
ENVELOPE_DEPTH = 4
ENVELOPE_ITEMS = 1024
HEADER_RESERVE_BYTES = 2**20

Tree = Any
Buffer = bytes | bytearray | memoryview
FigureEncoder = Callable[[object], dict]
CallableEncoder = Callable[[object], "CallableRef | None"]

_JSON_INT_BITS = 1024  # larger ints use the "int" tag
_JSON_INT_CHARS = 320  # a 1024-bit int has 309 digits; longer JSON numbers are rejected
_MAX_INT_BITS = math.ceil(MAX_INT_DIGITS * math.log2(10))
_MAX_HEX_CHARS = _MAX_INT_BITS // 4 + 4
_MAX_REPR_CHARS = 300
_COALESCE_BYTES = 64 * 1024
_DTYPE_RE = re.compile(r"[<>|=][biufc](1|2|4|8|16|32)")
_HEX_RE = re.compile(r"-?0x[0-9a-f]+")
_DTYPE_RULE = "only bool, int, uint, float and complex dtypes can cross"
_CAUGHT = (Exception, SystemExit, GeneratorExit)  # what student code may raise while encoding
_NONFINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}
_HEADER_LEN = struct.Struct(">I")
_BUF_LEN = struct.Struct(">Q")

# Exact numpy scalar types that cross as Python scalars, with their converter.
_PYTHON_SCALAR = {"b": bool, "i": int, "u": int, "f": float, "c": complex}
_NUMPY_SCALARS: dict[type, type] = {
    np.dtype(code).type: _PYTHON_SCALAR[np.dtype(code).kind]
    for code in "?" + np.typecodes["AllInteger"] + np.typecodes["AllFloat"]
}


class _Repr(reprlib.Repr):
    """reprlib limits, but a raising ``__repr__`` propagates (reprlib's own fallback
    trusts ``x.__class__``, which a student object can fake)."""

    def repr_instance(self, x: object, level: int) -> str:
        s = _text(builtins.repr(x))
        if len(s) > self.maxother:
            half = max(0, (self.maxother - 3) // 2)
            s = s[:half] + "..." + s[len(s) - half :]
        return s


_REPR = _Repr()
_REPR.maxstring = _REPR.maxother = _MAX_REPR_CHARS // 2
_REPR.maxlevel = 3


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
_REF_ID_RE = re.compile(r"[A-Za-z0-9_.:-]{1,64}")


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

    Walks only the exact containers :func:`decode` builds (list, tuple, dict);
    containers holding no ref are returned as they are, not copied.
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


# --------------------------------------------------------------------------
# encoding


def encode(
    value: object,
    *,
    max_depth: int = MAX_DEPTH,
    max_items: int = MAX_ITEMS,
    figure_encoder: FigureEncoder | None = None,
    buffers: list[Buffer] | None = None,
    callable_encoder: CallableEncoder | None = None,
) -> tuple[Tree, list[Buffer]]:
    """Encode ``value`` as ``(tree, buffers)``.

    Never raises for what the value is: anything that cannot cross (other
    types, subclasses, odd dtypes, objects whose methods raise) becomes an
    ``"unsupported"`` node. Raises :class:`ProtocolError` only when the value
    is nested deeper than ``max_depth`` or has more than ``max_items`` nodes.

    ``figure_encoder`` (worker side only) turns a matplotlib ``Figure`` (or an
    ``Axes``, through its figure) into figure data. ``buffers``, if given,
    receives the buffers (indices continue after its current length); on
    error it is left as it was. ``callable_encoder``, if given, is asked for a
    :class:`CallableRef` for each callable that is not otherwise plain data
    (it may return ``None`` to refuse); without it such values are unsupported.
    """
    bufs: list[Buffer] = [] if buffers is None else buffers
    start = len(bufs)
    encoder = _Encoder(
        bufs, max_depth=max_depth, max_items=max_items, figure_encoder=figure_encoder,
        callable_encoder=callable_encoder,
    )
    try:
        tree = encoder.encode(value, 0)
    except BaseException:
        del bufs[start:]
        raise
    return tree, bufs


def encode_result(
    value: object,
    *,
    figure_encoder: FigureEncoder | None = None,
    max_depth: int = MAX_DEPTH - ENVELOPE_DEPTH,
    max_items: int = MAX_ITEMS - ENVELOPE_ITEMS,
    max_bytes: int = MAX_FRAME_BYTES - HEADER_RESERVE_BYTES,
    buffers: list[Buffer] | None = None,
    callable_encoder: CallableEncoder | None = None,
) -> tuple[Tree, list[Buffer]]:
    """Encode a student's value for sending; never raises.

    Like :func:`encode`, but a value over a limit (depth, items, or buffers
    totalling more than ``max_bytes``) becomes one ``"unsupported"`` node
    whose reason names the limit. The default limits leave room for a message
    envelope around the tree, so the receiver's default limits accept it.
    """
    bufs: list[Buffer] = [] if buffers is None else buffers
    start = len(bufs)
    try:
        tree, _ = encode(
            value,
            max_depth=max_depth,
            max_items=max_items,
            figure_encoder=figure_encoder,
            buffers=bufs,
            callable_encoder=callable_encoder,
        )
    except ProtocolError as exc:
        return _unsupported(value, str(exc)), bufs
    except _CAUGHT as exc:  # defensive: encode does not raise these
        del bufs[start:]
        return _unsupported(value, f"encoding failed with {_type_name(type(exc))}"), bufs
    size = sum(_BUF_LEN.size + _nbytes(b) for b in bufs[start:])
    if size > max_bytes:
        del bufs[start:]
        reason = f"value needs {_size(size)}, more than the {_size(max_bytes)} limit for a result"
        return _unsupported(value, reason), bufs
    return tree, bufs


class _Encoder:
    """One encoding pass: the buffers found so far and the item count."""

    def __init__(
        self,
        buffers: list[Buffer],
        *,
        max_depth: int,
        max_items: int,
        figure_encoder: FigureEncoder | None,
        callable_encoder: CallableEncoder | None = None,
    ) -> None:
        self.buffers = buffers
        self.callable_encoder = callable_encoder
        self.max_depth = max_depth
        self.max_items = max_items
        self.figure_encoder = figure_encoder
        self.items = 0

    def encode(self, x: object, depth: int) -> Tree:
        self.items += 1
        if self.items > self.max_items:
            raise ProtocolError(f"value has more than {self.max_items} items")
        start = len(self.buffers)
        try:
            return self._dispatch(x, type(x), depth)
        except ProtocolError:
            raise
        except _CAUGHT as exc:  # student code (repr, properties) raised
            del self.buffers[start:]
            return _unsupported(x, f"encoding raised {_type_name(type(exc))}")

    def _dispatch(self, x: Any, t: type, depth: int) -> Tree:
        if t in _NUMPY_SCALARS:
            x = _NUMPY_SCALARS[t](x)
            t = type(x)
        if x is None or t is bool:
            return x
        if t is int:
            return _encode_int(x)
        if t is float:
            return _encode_float(x)
        if t is complex:
            return {"$t": "complex", "re": _encode_float(x.real), "im": _encode_float(x.imag)}
        if t is str:
            if len(x) > MAX_STR_CHARS:
                reason = f"str of {len(x)} characters exceeds the {MAX_STR_CHARS} limit"
                return _unsupported(x, reason)
            return x
        if t is list:
            return self._sequence(x, depth)
        if t is tuple:
            return {"$t": "tuple", "items": self._sequence(x, depth)}
        if t is dict:
            return self._dict(x, depth)
        if t is np.ndarray:
            return self._ndarray(x)
        if t is bytes:
            return {"$t": "bytes", "buf": self._add_buffer(x)}
        if t is Unsupported:
            fields = {"type": _text(x.type), "repr": _text(x.repr), "reason": _text(x.reason)}
            return {"$t": "unsupported", **fields}
        if t is CallableRef:
            return _encode_ref(x)
        if _is_matplotlib(t):
            return self._matplotlib(x, t, depth)
        if self.callable_encoder is not None and callable(x):  # callable(): no user code runs
            ref = self.callable_encoder(x)
            if type(ref) is CallableRef:
                return _encode_ref(ref)
            return _unsupported(x, "no more functions can be returned in this call")
        return _unsupported(x, _unsupported_reason(t))

    def _enter(self, depth: int, n: int) -> None:
        if depth >= self.max_depth:
            raise ProtocolError(f"value is nested deeper than {self.max_depth} levels")
        if self.items + n > self.max_items:
            raise ProtocolError(f"value has more than {self.max_items} items")

    def _sequence(self, x: list | tuple, depth: int) -> list:
        items = tuple(x)  # a snapshot: a student's __repr__ may mutate the list
        self._enter(depth, len(items))
        return [self.encode(item, depth + 1) for item in items]

    def _dict(self, x: dict, depth: int) -> Tree:
        pairs = list(x.items())
        self._enter(depth, len(pairs))
        if any(type(k) is not str for k, _ in pairs):
            return _unsupported(x, "dict keys must all be str")
        if any(len(k) > MAX_STR_CHARS for k, _ in pairs):
            return _unsupported(x, f"dict key longer than {MAX_STR_CHARS} characters")
        if any(k == "$t" for k, _ in pairs):
            return {"$t": "dict", "items": [[k, self.encode(v, depth + 1)] for k, v in pairs]}
        return {k: self.encode(v, depth + 1) for k, v in pairs}

    def _ndarray(self, x: np.ndarray) -> Tree:
        dtype = x.dtype
        if not _plain_dtype(dtype) or not _DTYPE_RE.fullmatch(dtype.str):
            reason = f"arrays of dtype {dtype.str} cannot cross; {_DTYPE_RULE}"
            return _unsupported(x, reason)
        if x.ndim > MAX_NDIM:
            return _unsupported(x, f"arrays of more than {MAX_NDIM} dimensions cannot cross")
        if x.nbytes > MAX_FRAME_BYTES:  # before copying: a broadcast view can be huge
            reason = f"array of {_size(x.nbytes)} exceeds the {_size(MAX_FRAME_BYTES)} frame limit"
            return _unsupported(x, reason)
        contiguous = x if x.flags.c_contiguous else x.copy(order="C")
        data = memoryview(contiguous.reshape(-1).view(np.uint8))
        index = self._add_buffer(data)
        return {"$t": "nd", "dtype": dtype.str, "shape": list(x.shape), "buf": index}

    def _matplotlib(self, x: object, t: type, depth: int) -> Tree:
        figure = _matplotlib_figure(x, t)
        if figure is None:
            return _unsupported(x, "matplotlib objects other than Figure and Axes cannot cross")
        if self.figure_encoder is None:
            return _unsupported(x, "figures need a figure encoder (given on the worker side only)")
        try:
            data = self.figure_encoder(figure)
        except _CAUGHT as exc:
            error = f"{_type_name(type(exc))}: {_safe_str(exc)}"
            return _unsupported(x, f"figure could not be converted: {error}")
        if type(data) is not dict or data.get("$t") != "figure":
            return _unsupported(x, "the figure encoder did not return figure data")
        pairs = [(k, v) for k, v in data.items() if k != "$t"]
        if any(type(k) is not str for k, _ in pairs):
            return _unsupported(x, "figure data keys must all be str")
        self._enter(depth, len(pairs))
        node: dict[str, Tree] = {"$t": "figure"}
        for k, v in pairs:
            node[k] = self.encode(v, depth + 1)
        return node

    def _add_buffer(self, data: Buffer) -> int:
        self.buffers.append(data)
        return len(self.buffers) - 1


def _encode_ref(ref: CallableRef) -> Tree:
    node = {"$t": "fn", "id": _text(ref.id), "name": _text(ref.name)[:_MAX_REPR_CHARS]}
    if ref.safe:
        node["safe"] = _text(ref.safe)
    return node


def _encode_int(x: int) -> Tree:
    bits = x.bit_length()
    if bits <= _JSON_INT_BITS:
        return x
    if bits > _MAX_INT_BITS:
        digits = int(bits * math.log10(2)) + 1
        reason = f"int of about {digits} digits exceeds the {MAX_INT_DIGITS}-digit limit"
        return _unsupported(x, reason)
    return {"$t": "int", "hex": hex(x)}


def _encode_float(x: float) -> Tree:
    if math.isfinite(x):
        return x
    return {"$t": "float", "v": "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")}


def _matplotlib_figure(x: Any, t: type) -> object | None:
    """The Figure behind ``x`` if ``x`` is a matplotlib Figure or Axes (by its type's name)."""
    name = type.__getattribute__(t, "__name__")
    if name == "Figure":
        return x
    if name.endswith("Axes") or name == "AxesSubplot":
        try:
            return x.get_figure(root=True)  # matplotlib >= 3.10: the root figure, not a SubFigure
        except TypeError:
            return x.figure
    return None


def _unsupported_reason(t: type) -> str:
    if issubclass(t, np.ndarray):
        return "ndarray subclasses cannot cross; return a plain numpy array (np.asarray)"
    if issubclass(t, np.generic):
        return "numpy scalars of this kind cannot cross; return a number"
    if issubclass(t, (list, tuple, dict, int, float, complex, str, bytes)):
        return (
            "subclasses of built-in types cannot cross;"
            " return a plain list, tuple, dict, number or str"
        )
    return (
        "values of this type cannot cross;"
        " return numbers, strings, lists, tuples, dicts or numpy arrays"
    )


def _is_matplotlib(t: type) -> bool:
    """Whether ``t`` comes from matplotlib (by its ``__module__``: never isinstance)."""
    module = type.__getattribute__(t, "__module__")
    return type(module) is str and module.startswith(("matplotlib.", "mpl_toolkits."))


def _unsupported(x: object, reason: str) -> dict[str, str]:
    """An ``"unsupported"`` node for ``x``; never raises."""
    fields = {"type": _type_name(type(x)), "repr": _safe_repr(x), "reason": reason}
    return {"$t": "unsupported", **fields}


def _type_name(t: type) -> str:
    """``module.qualname`` of a type (just ``qualname`` for builtins); never raises."""
    try:
        module = type.__getattribute__(t, "__module__")
        qualname = type.__getattribute__(t, "__qualname__")
        qualname = _text(qualname) if isinstance(qualname, str) else "?"
        if type(module) is str and module != "builtins":
            return f"{module}.{qualname}"[:_MAX_REPR_CHARS]
        return qualname[:_MAX_REPR_CHARS]
    except _CAUGHT:
        return "?"


def _safe_repr(x: object) -> str:
    """A short repr of ``x``; never raises, whatever ``__repr__`` does."""
    try:
        return _text(_REPR.repr(x))[:_MAX_REPR_CHARS]
    except _CAUGHT as exc:
        return f"<{_type_name(type(x))} object; repr raised {_type_name(type(exc))}>"


def _safe_str(exc: BaseException) -> str:
    try:
        return _text(str(exc))[:_MAX_REPR_CHARS]
    except _CAUGHT:
        return "?"


def _text(s: object) -> str:
    """An exact ``str`` from a str or str subclass, without calling its methods."""
    if type(s) is str:
        return s
    if isinstance(s, str):
        return str.encode(s, "utf-8", "surrogatepass").decode("utf-8", "surrogatepass")
    return "?"


# --------------------------------------------------------------------------
# decoding


def decode(
    tree: Tree,
    buffers: Sequence[Buffer] = (),
    *,
    max_depth: int = MAX_DEPTH,
    max_items: int = MAX_ITEMS,
) -> object:
    """Rebuild a value from ``(tree, buffers)``, validating everything.

    Only ``None``, ``bool``, ``int``, ``float``, ``complex``, ``str``,
    ``bytes``, ``list``, ``tuple``, ``dict``, base-class ``ndarray`` (via
    ``np.frombuffer(...).copy()``), :class:`Unsupported` and
    :class:`CallableRef` are ever built.
    Figure nodes become plain dicts (with ``"$t": "figure"`` and ``"png"``
    as bytes). Raises :class:`ProtocolError` naming
    what was wrong for any malformed tree.
    """
    decoder = _Decoder(buffers, max_depth=max_depth, max_items=max_items)
    try:
        value = decoder.decode(tree, 0)
    except RecursionError:
        raise ProtocolError("value is nested too deeply to decode") from None
    decoder.check_all_used()
    return value


class _Decoder:
    """One decoding pass: the buffers, which are used, and the item count."""

    def __init__(self, buffers: Sequence[Buffer], *, max_depth: int, max_items: int) -> None:
        self.buffers = list(buffers)
        self.used = [False] * len(self.buffers)
        self.max_depth = max_depth
        self.max_items = max_items
        self.items = 0
        self.handlers: dict[str, Callable[[dict, int], object]] = {
            "float": self._float,
            "int": self._int,
            "complex": self._complex,
            "tuple": self._tuple,
            "dict": self._escaped_dict,
            "nd": self._ndarray,
            "bytes": self._bytes,
            "figure": self._figure,
            "unsupported": self._unsupported,
            "fn": self._ref,
        }

    def decode(self, node: Tree, depth: int) -> object:
        self.items += 1
        if self.items > self.max_items:
            raise ProtocolError(f"value has more than {self.max_items} items")
        t = type(node)
        if node is None or t is bool:
            return node
        if t is int:
            if node.bit_length() > _JSON_INT_BITS:
                raise ProtocolError("an int of more than 1024 bits must use the 'int' tag")
            return node
        if t is float:
            if not math.isfinite(node):
                raise ProtocolError("non-finite float without a 'float' tag")
            return node
        if t is str:
            return _check_str(node, "str")
        if t is list:
            self._enter(depth, len(node))
            return [self.decode(item, depth + 1) for item in node]
        if t is dict:
            if "$t" not in node:
                self._enter(depth, len(node))
                return {_check_key(k): self.decode(v, depth + 1) for k, v in node.items()}
            tag = node["$t"]
            handler = self.handlers.get(tag) if type(tag) is str else None
            if handler is None:
                known = sorted(self.handlers)
                raise ProtocolError(f"unknown tag {_short(tag)}; expected one of {known}")
            return handler(node, depth)
        raise ProtocolError(f"tree node of type {_type_name(t)} is not JSON")

    def check_all_used(self) -> None:
        for i, used in enumerate(self.used):
            if not used:
                raise ProtocolError(f"buffer {i} is not referenced by the value")

    def _enter(self, depth: int, n: int) -> None:
        if depth >= self.max_depth:
            raise ProtocolError(f"value is nested deeper than {self.max_depth} levels")
        if self.items + n > self.max_items:
            raise ProtocolError(f"value has more than {self.max_items} items")

    def _float(self, node: dict, depth: int) -> float:
        _expect_keys(node, {"v"})
        v = node["v"]
        if type(v) is not str or v not in _NONFINITE:
            raise ProtocolError(f"'float' tag needs v in {sorted(_NONFINITE)}; got {_short(v)}")
        return _NONFINITE[v]

    def _int(self, node: dict, depth: int) -> int:
        _expect_keys(node, {"hex"})
        s = node["hex"]
        if type(s) is not str or len(s) > _MAX_HEX_CHARS or not _HEX_RE.fullmatch(s):
            raise ProtocolError(
                f"'int' tag needs a lower-case hex string of at most {_MAX_HEX_CHARS} characters"
            )
        return int(s, 16)

    def _complex(self, node: dict, depth: int) -> complex:
        _expect_keys(node, {"re", "im"})
        return complex(_float_part(node["re"], "re"), _float_part(node["im"], "im"))

    def _tuple(self, node: dict, depth: int) -> tuple:
        _expect_keys(node, {"items"})
        items = node["items"]
        if type(items) is not list:
            raise ProtocolError("'tuple' items must be a list")
        self._enter(depth, len(items))
        return tuple(self.decode(item, depth + 1) for item in items)

    def _escaped_dict(self, node: dict, depth: int) -> dict:
        _expect_keys(node, {"items"})
        items = node["items"]
        if type(items) is not list:
            raise ProtocolError("'dict' items must be a list of [key, value] pairs")
        self._enter(depth, len(items))
        out: dict[str, object] = {}
        for pair in items:
            if type(pair) is not list or len(pair) != 2 or type(pair[0]) is not str:
                raise ProtocolError("'dict' items must be [key, value] pairs with str keys")
            key = _check_key(pair[0])
            if key in out:
                raise ProtocolError(f"'dict' has the key {_short(key)} twice")
            out[key] = self.decode(pair[1], depth + 1)
        return out

    def _ndarray(self, node: dict, depth: int) -> np.ndarray:
        _expect_keys(node, {"dtype", "shape", "buf"})
        dtype = _check_dtype(node["dtype"])
        shape = _check_shape(node["shape"])
        index = node["buf"]
        data = self._take(index)
        count = math.prod(shape)
        needed = count * dtype.itemsize
        if needed != data.nbytes:
            raise ProtocolError(
                f"array of shape {tuple(shape)} and dtype {dtype.str} needs {needed} bytes;"
                f" buffer {index} has {data.nbytes}"
            )
        try:
            return np.frombuffer(data, dtype=dtype).reshape(shape).copy()
        except (ValueError, TypeError, OverflowError, MemoryError) as exc:
            raise ProtocolError(f"array of shape {tuple(shape)} cannot be built: {exc}") from None

    def _bytes(self, node: dict, depth: int) -> bytes:
        _expect_keys(node, {"buf"})
        return bytes(self._take(node["buf"]))

    def _figure(self, node: dict, depth: int) -> dict:
        self._enter(depth, len(node) - 1)
        out: dict[str, object] = {"$t": "figure"}
        for k, v in node.items():
            if k != "$t":
                out[_check_key(k)] = self.decode(v, depth + 1)
        if type(out.get("axes")) is not list:
            raise ProtocolError("'figure' needs 'axes', a list")
        if type(out.get("png")) is not bytes:
            raise ProtocolError("'figure' needs 'png', bytes")
        return out

    def _unsupported(self, node: dict, depth: int) -> Unsupported:
        _expect_keys(node, {"type", "repr"}, optional={"reason"})
        fields = {k: node.get(k, "") for k in ("type", "repr", "reason")}
        for k, v in fields.items():
            if type(v) is not str:
                raise ProtocolError(f"'unsupported' field {k!r} must be a str")
            _check_str(v, f"'unsupported' field {k!r}")
        return Unsupported(**fields)

    def _ref(self, node: dict, depth: int) -> CallableRef:
        _expect_keys(node, {"id", "name"}, optional={"safe"})
        ref_id, name, safe = node["id"], node["name"], node.get("safe", "")
        if type(ref_id) is not str or not _REF_ID_RE.fullmatch(ref_id):
            raise ProtocolError("'fn' id must be 1 to 64 letters, digits or _.:-")
        if type(name) is not str or len(name) > _MAX_REPR_CHARS:
            raise ProtocolError(f"'fn' name must be a str of at most {_MAX_REPR_CHARS} characters")
        if type(safe) is not str or (safe and safe not in SAFE_FUNCTIONS):
            raise ProtocolError(f"'fn' safe name {_short(safe)} is not one of SAFE_FUNCTIONS")
        return CallableRef(ref_id, name, safe)

    def _take(self, index: object) -> memoryview:
        if type(index) is not int or not 0 <= index < len(self.buffers):
            n = len(self.buffers)
            raise ProtocolError(f"buffer index {_short(index)} is not one of the {n} buffers")
        if self.used[index]:
            raise ProtocolError(f"buffer {index} is referenced twice")
        self.used[index] = True
        try:
            view = memoryview(self.buffers[index])
        except TypeError:
            raise ProtocolError(f"buffer {index} is not bytes-like") from None
        if not view.c_contiguous:
            raise ProtocolError(f"buffer {index} is not contiguous")
        return view if view.format == "B" and view.ndim == 1 else view.cast("B")


def _expect_keys(node: dict, required: set[str], *, optional: Set[str] = frozenset()) -> None:
    keys = set(node) - {"$t"}
    if not required <= keys or not keys <= required | optional:
        tag = node["$t"]
        want = sorted(required | optional)
        raise ProtocolError(f"tag {tag!r} needs keys {want}; got {sorted(map(_short, keys))}")


def _float_part(v: object, name: str) -> float:
    if type(v) is float and math.isfinite(v):
        return v
    if type(v) is dict and set(v) == {"$t", "v"} and v["$t"] == "float" and v["v"] in _NONFINITE:
        return _NONFINITE[v["v"]]
    raise ProtocolError(f"'complex' part {name!r} must be a float or 'float' tag; got {_short(v)}")


def _check_dtype(s: object) -> np.dtype:
    if type(s) is not str or not _DTYPE_RE.fullmatch(s):
        raise ProtocolError(f"array dtype {_short(s)} is not allowed; {_DTYPE_RULE}")
    try:
        dtype = np.dtype(s)
    except TypeError:
        raise ProtocolError(f"array dtype {s!r} is not understood") from None
    if not _plain_dtype(dtype):
        raise ProtocolError(f"array dtype {s!r} is not allowed; {_DTYPE_RULE}")
    return dtype


def _plain_dtype(dtype: np.dtype) -> bool:
    """Bool, int, uint, float or complex, without objects, fields or sub-arrays."""
    return (
        dtype.kind in "biufc"
        and not dtype.hasobject
        and dtype.fields is None
        and dtype.subdtype is None
    )


def _check_shape(shape: object) -> list[int]:
    if type(shape) is not list or len(shape) > MAX_NDIM:
        raise ProtocolError(f"array shape must be a list of at most {MAX_NDIM} ints")
    for n in shape:
        if type(n) is not int or n < 0:
            raise ProtocolError(f"array shape entries must be non-negative ints; got {_short(n)}")
    return shape


def _check_str(s: str, what: str) -> str:
    if len(s) > MAX_STR_CHARS:
        raise ProtocolError(f"{what} of {len(s)} characters exceeds the {MAX_STR_CHARS} limit")
    return s


def _check_key(k: object) -> str:
    if type(k) is not str:
        raise ProtocolError(f"dict key {_short(k)} is not a str")
    return _check_str(k, "dict key")


def _short(x: object) -> str:
    """A short repr of tree data (plain JSON types only) for error messages."""
    text = repr(x) if type(x) in (str, int, float, bool, type(None)) else f"<{_type_name(type(x))}>"
    return text if len(text) <= 60 else text[:57] + "..."


# --------------------------------------------------------------------------
# framing


def send_frame(
    sock: socket.socket,
    tree: Tree,
    buffers: Sequence[Buffer],
    *,
    max_bytes: int = MAX_FRAME_BYTES,
) -> int:
    """Send one frame holding ``tree`` and ``buffers``; return its size in bytes.

    Raises :class:`ProtocolError` before sending anything if the tree is not
    plain JSON or the frame would exceed ``max_bytes``; socket errors
    (``OSError``, ``TimeoutError`` from the socket's own timeout) propagate.
    """
    lengths = [_nbytes(b) for b in buffers]
    try:
        text = json.dumps({"v": tree, "bufs": lengths}, allow_nan=False, separators=(",", ":"))
    except (TypeError, ValueError, RecursionError) as exc:
        raise ProtocolError(f"tree is not plain JSON: {exc}") from None
    header = text.encode("ascii")  # ensure_ascii: lone surrogates are escaped, not lost
    total = _HEADER_LEN.size + len(header) + sum(_BUF_LEN.size + n for n in lengths)
    if total > max_bytes:
        raise ProtocolError(f"frame of {_size(total)} exceeds the {_size(max_bytes)} limit")
    pending = bytearray(_HEADER_LEN.pack(len(header)))
    pending += header
    for data, n in zip(buffers, lengths):
        pending += _BUF_LEN.pack(n)
        if n <= _COALESCE_BYTES:
            pending += data
        else:
            sock.sendall(pending)
            pending = bytearray()
            sock.sendall(data)
    if pending:
        sock.sendall(pending)
    return total


def recv_frame(
    sock: socket.socket, *, max_bytes: int = MAX_FRAME_BYTES, timeout: float | None = None
) -> tuple[Tree, list[bytearray]]:
    """Receive one frame; return ``(tree, buffers)`` (tree parsed, not yet decoded).

    ``timeout`` is a deadline in seconds for the whole frame (``None``: leave
    the socket's own timeout as it is). Raises :class:`ProtocolError` for a
    malformed frame or one larger than ``max_bytes`` (checked from the header,
    before any payload is read), :class:`EOFError` if the peer closed the
    connection, :class:`TimeoutError` when the deadline passes.
    """
    deadline = None if timeout is None else time.monotonic() + timeout
    previous = sock.gettimeout()
    # The socket's timeout is changed only when a read has to wait for the deadline
    # (see _recv_exactly), and put back only then; a socket that has a timeout of its
    # own is read as before (its reads wait in poll, so they cannot be tried at once).
    waited = [deadline is not None and previous is not None]
    try:
        raw = _recv_exactly(sock, _HEADER_LEN.size, deadline, "frame length", waited)
        (header_len,) = _HEADER_LEN.unpack(raw)
        if _HEADER_LEN.size + header_len > max_bytes:
            limit = _size(max_bytes)
            raise ProtocolError(f"frame header of {_size(header_len)} exceeds the {limit} limit")
        tree, lengths = _parse_header(_recv_exactly(sock, header_len, deadline, "frame header",
                                                    waited))
        total = _HEADER_LEN.size + header_len + sum(_BUF_LEN.size + n for n in lengths)
        if total > max_bytes:
            raise ProtocolError(f"frame of {_size(total)} exceeds the {_size(max_bytes)} limit")
        buffers = []
        for i, n in enumerate(lengths):
            raw = _recv_exactly(sock, _BUF_LEN.size, deadline, f"length of buffer {i}", waited)
            (announced,) = _BUF_LEN.unpack(raw)
            if announced != n:
                raise ProtocolError(
                    f"buffer {i} is {n} bytes in the header but {announced} in its prefix"
                )
            buffers.append(_recv_exactly(sock, n, deadline, f"buffer {i}", waited))
        return tree, buffers
    finally:
        if waited[0]:
            sock.settimeout(previous)


def send_message(
    sock: socket.socket,
    obj: object,
    *,
    figure_encoder: FigureEncoder | None = None,
    max_depth: int = MAX_DEPTH,
    max_items: int = MAX_ITEMS,
    max_bytes: int = MAX_FRAME_BYTES,
    callable_encoder: CallableEncoder | None = None,
) -> int:
    """Encode ``obj`` (see :func:`encode`) and send it as one frame; return the frame size.

    Raises :class:`ProtocolError` before sending anything if ``obj`` is over a
    limit.
    """
    tree, buffers = encode(
        obj, max_depth=max_depth, max_items=max_items, figure_encoder=figure_encoder,
        callable_encoder=callable_encoder,
    )
    return send_frame(sock, tree, buffers, max_bytes=max_bytes)


def recv_message(
    sock: socket.socket,
    *,
    max_bytes: int = MAX_FRAME_BYTES,
    timeout: float | None = None,
    max_depth: int = MAX_DEPTH,
    max_items: int = MAX_ITEMS,
) -> object:
    """Receive one frame and decode it (see :func:`recv_frame` and :func:`decode`)."""
    tree, buffers = recv_frame(sock, max_bytes=max_bytes, timeout=timeout)
    return decode(tree, buffers, max_depth=max_depth, max_items=max_items)


def _recv_exactly(sock: socket.socket, n: int, deadline: float | None, what: str,
                  waited: list[bool]) -> bytearray:
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    if deadline is not None and n and not waited[0]:
        # The peer writes a frame with one send, so its bytes are usually here already:
        # take them without a deadline. Setting the socket's timeout for the read (one
        # ioctl each way, and a poll before every read) cost more than the read itself.
        try:
            got = sock.recv_into(view, n, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            got = 0
        else:
            if got == 0:
                raise EOFError(f"connection closed after 0 of {n} bytes of the {what}")
    while got < n:
        if deadline is not None:
            waited[0] = True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"timed out waiting for the {what} ({got} of {n} bytes read)")
            sock.settimeout(remaining)
        k = sock.recv_into(view[got:])
        if k == 0:
            raise EOFError(f"connection closed after {got} of {n} bytes of the {what}")
        got += k
    return buf


def _parse_header(raw: bytearray) -> tuple[Tree, list[int]]:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError("frame header is not UTF-8") from None
    try:
        header = json.loads(
            text,
            parse_constant=_reject_constant,
            parse_int=_parse_int,
            object_pairs_hook=_unique_keys,
        )
    except RecursionError:
        raise ProtocolError("frame header is nested too deeply") from None
    except ValueError as exc:
        raise ProtocolError(f"frame header is not valid JSON: {exc}") from None
    if type(header) is not dict or set(header) != {"v", "bufs"}:
        raise ProtocolError("frame header must be a JSON object with keys 'v' and 'bufs'")
    lengths = header["bufs"]
    if type(lengths) is not list or len(lengths) > MAX_ITEMS:
        raise ProtocolError(f"'bufs' must be a list of at most {MAX_ITEMS} lengths")
    for n in lengths:
        if type(n) is not int or n < 0:
            raise ProtocolError(f"buffer lengths must be non-negative ints; got {_short(n)}")
    return header["v"], lengths


def _reject_constant(name: str) -> float:
    raise ProtocolError(f"frame header contains {name}; non-finite floats must use the 'float' tag")


def _parse_int(s: str) -> int:
    if len(s) > _JSON_INT_CHARS:
        raise ProtocolError(f"JSON int of {len(s)} digits; ints over 1024 bits use the 'int' tag")
    return int(s)


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        counts = collections.Counter(k for k, _ in pairs)
        duplicate = next(k for k, n in counts.items() if n > 1)
        raise ProtocolError(f"frame header has the key {_short(duplicate)} twice in one object")
    return out


def _nbytes(data: Buffer) -> int:
    return len(data) if type(data) in (bytes, bytearray) else memoryview(data).nbytes


def _size(n: int) -> str:
    if n >= 2**20:
        return f"{n / 2**20:.1f}".removesuffix(".0") + " MiB"
    if n >= 2**10:
        return f"{n / 2**10:.1f}".removesuffix(".0") + " KiB"
    return f"{n} bytes"
