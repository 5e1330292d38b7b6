"""Plain-data encoding of values at the boundary between grader and worker.

A value becomes a JSON tree and a list of buffers (:func:`encode`), and a tree
and its buffers become a value again (:func:`decode`); :mod:`autograder.boundary.frames`
carries them over a socket. This module is imported by both sides: the trusted
grader and the untrusted worker that runs student code. It therefore imports
only the standard library, numpy and :mod:`autograder.errors` (and the
boundary's own limits), and it never imports :mod:`pickle`, never calls
``eval``, and never calls a constructor chosen by the data.

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
    a value that could not be encoded; decoded to
    :class:`~autograder.boundary.values.Unsupported`.
``{"$t": "fn", "id": str, "name": str, "safe": str}``
    a reference to a function that stays on the side that sent it (``safe``
    optional): a function a check passes to student code, or one the student
    returns. Decoded to :class:`~autograder.boundary.values.CallableRef`, plain
    data; each side turns refs into its own calling objects
    (:mod:`autograder.engine.callbacks` on the trusted side,
    :mod:`autograder.worker.loop` in the worker), so no function's code ever
    crosses. ``safe`` names a function of
    :data:`~autograder.boundary.values.SAFE_FUNCTIONS` that the worker may
    evaluate itself.

Every buffer must be referenced exactly once. Depth counts nested containers
(list, tuple, dict, figure); items count every value node.

Trees compose: a plain dict with str keys (no ``"$t"``) whose values are trees
is a tree, so the worker can wrap the tree from :func:`encode_result` in a
JSON envelope, e.g. ``{"status": "ok", "value": tree}``, and send it with
:func:`~autograder.boundary.frames.send_frame`. :func:`encode_result` leaves
room for such an envelope in its default limits. The limits themselves are in
:mod:`autograder.boundary.limits`.
"""

from __future__ import annotations

import builtins
import math
import re
import reprlib
from collections.abc import Callable, Sequence, Set
from typing import Any

import numpy as np

from autograder.boundary.limits import BUFFER_PREFIX, MAX_DEPTH, MAX_FRAME_BYTES, MAX_ITEMS
from autograder.boundary.values import SAFE_FUNCTIONS, CallableRef, Unsupported
from autograder.errors import ProtocolError

__all__ = [
    "MAX_STR_CHARS",
    "MAX_INT_DIGITS",
    "MAX_NDIM",
    "encode",
    "encode_result",
    "decode",
]

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
_MAX_INT_BITS = math.ceil(MAX_INT_DIGITS * math.log2(10))
_MAX_HEX_CHARS = _MAX_INT_BITS // 4 + 4
_MAX_REPR_CHARS = 300
_DTYPE_RE = re.compile(r"[<>|=][biufc](1|2|4|8|16|32)")
_HEX_RE = re.compile(r"-?0x[0-9a-f]+")
_DTYPE_RULE = "only bool, int, uint, float and complex dtypes can cross"
_CAUGHT = (Exception, SystemExit, GeneratorExit)  # what student code may raise while encoding
_NONFINITE = {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}
_REF_ID_RE = re.compile(r"[A-Za-z0-9_.:-]{1,64}")

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
    size = sum(BUFFER_PREFIX.size + nbytes(b) for b in bufs[start:])
    if size > max_bytes:
        del bufs[start:]
        limit = size_text(max_bytes)
        reason = f"value needs {size_text(size)}, more than the {limit} limit for a result"
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
            limit = size_text(MAX_FRAME_BYTES)
            reason = f"array of {size_text(x.nbytes)} exceeds the {limit} frame limit"
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
        decoder.check_all_used()
    except RecursionError:
        raise ProtocolError("value is nested too deeply to decode") from None
    finally:
        # The handlers (bound methods) make the decoder a reference cycle: without this
        # it would keep the frame's buffers (up to MAX_FRAME_BYTES) until the next garbage
        # collection; a loop of large callbacks kept gigabytes so.
        decoder.buffers.clear()
        decoder.handlers.clear()
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
                raise ProtocolError(f"unknown tag {short_repr(tag)}; expected one of {known}")
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
            raise ProtocolError(f"'float' tag needs v in {sorted(_NONFINITE)}; got {short_repr(v)}")
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
                raise ProtocolError(f"'dict' has the key {short_repr(key)} twice")
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
            raise ProtocolError(f"'fn' safe name {short_repr(safe)} is not one of SAFE_FUNCTIONS")
        return CallableRef(ref_id, name, safe)

    def _take(self, index: object) -> memoryview:
        if type(index) is not int or not 0 <= index < len(self.buffers):
            n = len(self.buffers)
            raise ProtocolError(f"buffer index {short_repr(index)} is not one of the {n} buffers")
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
        raise ProtocolError(f"tag {tag!r} needs keys {want}; got {sorted(map(short_repr, keys))}")


def _float_part(v: object, name: str) -> float:
    if type(v) is float and math.isfinite(v):
        return v
    if type(v) is dict and set(v) == {"$t", "v"} and v["$t"] == "float" and v["v"] in _NONFINITE:
        return _NONFINITE[v["v"]]
    raise ProtocolError(
        f"'complex' part {name!r} must be a float or 'float' tag; got {short_repr(v)}")


def _check_dtype(s: object) -> np.dtype:
    if type(s) is not str or not _DTYPE_RE.fullmatch(s):
        raise ProtocolError(f"array dtype {short_repr(s)} is not allowed; {_DTYPE_RULE}")
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
            raise ProtocolError(
                f"array shape entries must be non-negative ints; got {short_repr(n)}")
    return shape


def _check_str(s: str, what: str) -> str:
    if len(s) > MAX_STR_CHARS:
        raise ProtocolError(f"{what} of {len(s)} characters exceeds the {MAX_STR_CHARS} limit")
    return s


def _check_key(k: object) -> str:
    if type(k) is not str:
        raise ProtocolError(f"dict key {short_repr(k)} is not a str")
    return _check_str(k, "dict key")


def short_repr(x: object) -> str:
    """A short repr of tree data (plain JSON types only) for error messages."""
    text = repr(x) if type(x) in (str, int, float, bool, type(None)) else f"<{_type_name(type(x))}>"
    return text if len(text) <= 60 else text[:57] + "..."


def nbytes(data: Buffer) -> int:
    """The length of a buffer in bytes."""
    return len(data) if type(data) in (bytes, bytearray) else memoryview(data).nbytes


def size_text(n: int) -> str:
    """A size for messages: ``"12 bytes"``, ``"1.5 KiB"``, ``"64 MiB"``."""
    if n >= 2**20:
        return f"{n / 2**20:.1f}".removesuffix(".0") + " MiB"
    if n >= 2**10:
        return f"{n / 2**10:.1f}".removesuffix(".0") + " KiB"
    return f"{n} bytes"
