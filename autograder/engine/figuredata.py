"""Figure data received from the worker, validated and cut to the figure budget on the grader's side.

The worker reads a student's matplotlib figure into plain data
(:mod:`autograder.worker.figures`) and keeps to the budget of
:mod:`autograder.boundary.figurelimits`, but the worker runs the student's code:
whatever it claims, a figure could hold millions of points, huge strings, fields
of the wrong type or a "PNG" of any size. :func:`receive_figure` rebuilds each
figure from the fields checks read, with the types the module docstring of
:mod:`autograder.worker.figures` gives, within the budget; what is cut sets
``"truncated"``, what is dropped adds a note. Written by hand because the figure
data's schema is ours: no library knows it.
"""

from __future__ import annotations

import itertools
import math
import struct
from typing import Any, Callable

import numpy as np

from autograder.boundary import limits
from autograder.boundary.figurelimits import (
    MAX_ARTISTS,
    MAX_AXES,
    MAX_FIGURE_POINTS,
    MAX_FIGURE_TEXT,
    MAX_FIGURES,
    MAX_NOTES,
    MAX_PNG_BYTES,
    MAX_PNG_PIXELS,
    MAX_TEXT_CHARS,
)

__all__ = ["receive_figure", "receive_figures", "receive_value"]

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_CONTAINERS = (list, tuple, dict)
_CONTAINER_SET = frozenset(_CONTAINERS)


class _Drop(Exception):
    """A field or artist that is not what figure data holds; the message says why."""


class _Budget:
    """What one figure may still hold, what was cut, and the notes saying so."""

    def __init__(self) -> None:
        self.points = MAX_FIGURE_POINTS
        self.artists = MAX_ARTISTS
        self.text = MAX_FIGURE_TEXT
        self.truncated = False
        self.notes: list[str] = []

    def take(self, n: int) -> int:
        k = max(0, min(n, self.points))
        self.points -= k
        self.truncated = self.truncated or k < n
        return k

    def note(self, text: str) -> None:
        if len(self.notes) < MAX_NOTES:
            self.notes.append(text[:200])
        else:
            self.truncated = True

    def string(self, value: Any) -> str:
        if type(value) is not str:
            raise _Drop(f"a {type(value).__name__} where text belongs")
        k = min(len(value), MAX_TEXT_CHARS, self.text)
        self.text -= k
        self.truncated = self.truncated or k < len(value)
        return value[:k]


def receive_figures(figures: Any) -> list[dict]:
    """The figures of one answer, each validated (at most :data:`MAX_FIGURES`)."""
    if type(figures) not in (list, tuple):
        return []
    return [receive_figure(f) for f in figures[:MAX_FIGURES]]


def receive_value(value: Any, _depth: int = 0) -> Any:
    """``value`` with every figure in it (at any depth of lists, tuples and dicts)
    validated; containers holding no figure are returned as they are."""
    t = type(value)
    if t is dict:
        if value.get("$t") == "figure":
            return receive_figure(value)
        items = value.items()
        if _depth >= limits.MAX_DEPTH or not any(type(v) in _CONTAINERS for _, v in items):
            return value
        new = {k: receive_value(v, _depth + 1) for k, v in items}
        return value if all(new[k] is v for k, v in items) else new
    if t not in (list, tuple) or _depth >= limits.MAX_DEPTH:
        return value
    kinds = set(map(type, value))  # in C: a long list of numbers, or of points, is quick
    if not kinds & _CONTAINER_SET or (kinds <= {list, tuple} and not set(
            map(type, itertools.chain.from_iterable(value))) & _CONTAINER_SET):
        return value
    items = [receive_value(v, _depth + 1) for v in value]
    if all(a is b for a, b in zip(items, value)):
        return value
    return items if t is list else tuple(items)


def receive_figure(data: Any) -> dict:
    """Figure data rebuilt from ``data`` within the figure budget; never raises."""
    budget = _Budget()
    if type(data) is not dict:
        return _figure([], "", b"", True, [f"a {type(data).__name__} was sent as a figure"])
    axes = []
    given = _listed(data.get("axes"))
    if len(given) > MAX_AXES:
        budget.truncated = True
        budget.note(f"only the first {MAX_AXES} of {len(given)} axes were kept")
    for i, ax in enumerate(given[:MAX_AXES]):
        try:
            axes.append(_axes(ax, budget))
        except _Drop as why:
            budget.note(f"axes {i} was dropped: {why}")
    suptitle = _field(budget, "suptitle", lambda: budget.string(data.get("suptitle", "")), "")
    png = _field(budget, "picture", lambda: _png(data.get("png", b"")), b"")
    # the worker's own notes after the grader's, in the room left
    for note in _listed(data.get("notes"))[:MAX_NOTES]:
        if type(note) is str:
            budget.note(note)
    return _figure(axes, suptitle, png, data.get("truncated") is True or budget.truncated,
                   budget.notes)


def _figure(axes: list, suptitle: str, png: bytes, truncated: bool, notes: list[str]) -> dict:
    return {"$t": "figure", "axes": axes, "suptitle": suptitle, "png": png,
            "truncated": bool(truncated), "notes": notes}


def _listed(value: Any) -> list:
    return list(value) if type(value) in (list, tuple) else []


def _field(budget: _Budget, name: str, read: Callable[[], Any], default: Any) -> Any:
    try:
        return read()
    except _Drop as why:
        budget.note(f"{name} was dropped: {why}")
        return default


# -- axes ----------------------------------------------------------------------
def _axes(ax: Any, budget: _Budget) -> dict:
    if type(ax) is not dict:
        raise _Drop(f"a {type(ax).__name__}, not axes data")

    def text(name: str) -> str:
        return _field(budget, name, lambda: budget.string(ax.get(name, "")), "")

    return {
        "lines": _artists(ax, "lines", budget, _line),
        "collections": _artists(ax, "collections", budget, _collection),
        "patches": _artists(ax, "patches", budget, _patch),
        "images": _artists(ax, "images", budget, lambda image, b: _image(image)),
        "texts": _artists(ax, "texts", budget, lambda t, b: b.string(t)),
        "xlim": _field(budget, "xlim", lambda: _pair(ax.get("xlim")), [math.nan, math.nan]),
        "ylim": _field(budget, "ylim", lambda: _pair(ax.get("ylim")), [math.nan, math.nan]),
        "xlabel": text("xlabel"), "ylabel": text("ylabel"), "title": text("title"),
        "aspect": _field(budget, "aspect", lambda: _aspect(ax.get("aspect", "auto"), budget),
                         "auto"),
        "legend": _artists(ax, "legend", budget, lambda t, b: b.string(t)),
    }


def _artists(ax: dict, kind: str, budget: _Budget,
             read: Callable[[Any, _Budget], Any]) -> list:
    given = _listed(ax.get(kind))
    kept = []
    for i, artist in enumerate(given):
        if budget.artists <= 0:
            budget.truncated = True
            budget.note(f"only the first {MAX_ARTISTS} artists of the figure were kept")
            break
        budget.artists -= 1
        try:
            kept.append(read(artist, budget))
        except _Drop as why:
            budget.note(f"{kind} {i} was dropped: {why}")
    return kept


def _line(line: Any, budget: _Budget) -> dict:
    if type(line) is not dict:
        raise _Drop(f"a {type(line).__name__}, not line data")
    x, y = _floats(line.get("x")), _floats(line.get("y"))
    k = budget.take(min(x.size, y.size))
    return {"x": x[:k].copy(), "y": y[:k].copy(),
            **{name: budget.string(line.get(name, "")) for name in
               ("label", "color", "linestyle", "marker")}}


def _collection(coll: Any, budget: _Budget) -> dict:
    if type(coll) is not dict:
        raise _Drop(f"a {type(coll).__name__}, not collection data")
    offsets = _pairs(coll.get("offsets", np.empty((0, 2))))
    offsets = offsets[: budget.take(len(offsets))].copy()
    segments = []
    for piece in _listed(coll.get("segments")):
        vertices = _pairs(piece)
        k = budget.take(len(vertices))
        segments.append(vertices[:k].copy())
        if k < len(vertices):
            break
    array = coll.get("array")
    if array is not None:
        values = _floats(array, ravel=False)
        k = budget.take(values.size)
        array = values.copy() if k == values.size else values.reshape(-1)[:k].copy()
    return {"kind": budget.string(coll.get("kind", "")), "offsets": offsets,
            "segments": segments, "array": array}


def _patch(patch: Any, budget: _Budget) -> dict:
    if type(patch) is not dict:
        raise _Drop(f"a {type(patch).__name__}, not patch data")
    vertices = _pairs(patch.get("vertices"))
    return {"kind": budget.string(patch.get("kind", "")),
            "vertices": vertices[: budget.take(len(vertices))].copy()}


def _image(image: Any) -> dict:
    if type(image) is not dict:
        raise _Drop(f"a {type(image).__name__}, not image data")
    shape = _listed(image.get("shape"))
    if not 0 < len(shape) <= 3 or not all(type(n) is int and 0 <= n <= 2**31 for n in shape):
        raise _Drop("its shape is not 1 to 3 sizes")
    extent = _floats(image.get("extent"))
    if extent.size != 4:
        raise _Drop("its extent is not 4 numbers")
    return {"shape": list(shape), "extent": extent.tolist()}


# -- values --------------------------------------------------------------------
def _floats(value: Any, *, ravel: bool = True) -> np.ndarray:
    """``value`` as a float64 array (a view when it already is one), or _Drop."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biuf":
            raise _Drop(f"an array of dtype {value.dtype}, not numbers")
        array = value.astype(np.float64, copy=False)
    elif type(value) in (list, tuple) and len(value) <= MAX_FIGURE_POINTS and all(
            type(v) in (int, float, bool) for v in value):
        array = np.array(value, dtype=np.float64)
    else:
        raise _Drop(f"a {type(value).__name__}, not an array of numbers")
    return array.reshape(-1) if ravel else array


def _pairs(value: Any) -> np.ndarray:
    array = _floats(value, ravel=False)
    if array.ndim != 2 or array.shape[1] != 2:
        raise _Drop(f"points of shape {array.shape}, not (k, 2)")
    return array


def _pair(value: Any) -> list[float]:
    array = _floats(value)
    if array.size != 2:
        raise _Drop(f"{array.size} numbers, not 2")
    return array.tolist()


def _aspect(value: Any, budget: _Budget) -> str | float:
    if type(value) is str:
        return budget.string(value)
    if type(value) in (int, float):
        return float(value)
    raise _Drop(f"a {type(value).__name__}, not text or a number")


def _png(value: Any) -> bytes:
    """``value`` if it is a PNG within :data:`MAX_PNG_BYTES` and :data:`MAX_PNG_PIXELS`."""
    if type(value) is not bytes:
        raise _Drop(f"a {type(value).__name__}, not PNG bytes")
    if not value:
        return b""
    if len(value) > MAX_PNG_BYTES:
        raise _Drop(f"{len(value):,} bytes, more than {MAX_PNG_BYTES:,}")
    # the signature, then the IHDR chunk: length, b"IHDR", width, height (PNG spec, 11.2.2)
    if len(value) < 24 or value[:8] != _PNG_SIGNATURE or value[12:16] != b"IHDR":
        raise _Drop("not a PNG file")
    width, height = struct.unpack(">II", value[16:24])
    if width * height > MAX_PNG_PIXELS:
        raise _Drop(f"{width} x {height} pixels, more than {MAX_PNG_PIXELS:,}")
    return value
