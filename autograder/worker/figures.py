"""matplotlib figures as plain data plus a PNG, on the worker side.

Checks cannot hold a student's ``Figure`` (it would have to be unpickled in
the grader), so the worker reads what a check may want to compare out of the
figure: line data, scatter offsets, collection paths (contours, tripcolor,
fill_between), patches, images, texts, limits and labels, and renders a PNG
for feedback. Arrays are float64 ``ndarray`` so :mod:`autograder.boundary.codec`
sends them as binary buffers.

Extraction runs over student artists: every artist (and every axes field) is
read inside its own ``try``; a failure skips that item and adds a line to the
figure's ``"notes"`` instead of breaking the whole figure.

Figure data (a dict, the ``"$t"`` key marks it for the codec)::

    {"$t": "figure",
     "axes": [{"lines": [{"x", "y", "label", "color", "linestyle", "marker"}],
               "collections": [{"kind", "offsets", "segments", "array"}],
               "patches": [{"kind", "vertices"}],
               "images": [{"shape", "extent"}],
               "texts": [str], "xlim": [a, b], "ylim": [a, b],
               "xlabel": str, "ylabel": str, "title": str,
               "aspect": "equal" | "auto" | float, "legend": [str]}],
     "suptitle": str, "png": bytes, "truncated": bool, "notes": [str]}
"""

from __future__ import annotations

import io
import math
import sys
from collections.abc import Callable, Collection
from typing import Any

import matplotlib

# Switching the backend after pyplot is imported closes every figure: only choose it first.
if "matplotlib.pyplot" not in sys.modules:
    matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.colors import to_hex  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.path import Path  # noqa: E402

from autograder.boundary.figurelimits import (  # noqa: E402
    MAX_FIGURE_POINTS,
    MAX_PNG_PIXELS,
    MAX_TEXT_CHARS,
)

__all__ = [
    "figure_to_data",
    "open_figures_data",
    "figures_data",
    "open_figure_numbers",
    "close_all",
]

DEFAULT_DPI = 72
#: the budget of :mod:`autograder.boundary.figurelimits`, which the grader enforces again
#: on what it receives (this side runs the student's code: its limits are only a courtesy)
DEFAULT_MAX_POINTS = MAX_FIGURE_POINTS

_SKIP_CODES = (Path.STOP, Path.CLOSEPOLY)
_IDENTITY = object()  # marks "already in data coordinates"


class _Skip(Exception):
    """An artist whose data cannot be read as numbers; the message says why."""


class _Budget:
    """Points still allowed in one figure's data, and whether any were cut."""

    def __init__(self, max_points: int) -> None:
        self.left = max_points
        self.truncated = False

    def take(self, n: int) -> int:
        """How many of ``n`` points may be kept (and count them)."""
        k = min(n, self.left)
        self.left -= k
        if k < n:
            self.truncated = True
        return k


def figure_to_data(
    fig: Figure, *, dpi: float = DEFAULT_DPI, max_points: int = DEFAULT_MAX_POINTS
) -> dict:
    """Read a figure's data (see the module docstring) and render it as PNG.

    ``max_points`` caps the points kept over the whole figure (line points,
    offsets, path vertices, collection values); when it cuts anything,
    ``"truncated"`` is True. The PNG is rendered at ``dpi`` (lower for a
    figure of more than ``MAX_PNG_PIXELS``); if rendering fails, ``"png"`` is
    ``b""`` with a note. Raises ``TypeError`` only if ``fig`` is not a
    ``matplotlib.figure.Figure``; problems with single artists become notes.
    """
    if not isinstance(fig, Figure):
        raise TypeError(f"expected a matplotlib Figure; got {type(fig).__name__}")
    budget = _Budget(max_points)
    notes: list[str] = []
    axes = []
    for i, ax in enumerate(_attempt(notes, "list axes", fig.get_axes, [])):
        axes.append(_axes_data(ax, budget, notes, f"axes {i}"))
    return {
        "$t": "figure",
        "axes": axes,
        "suptitle": _attempt(notes, "suptitle", lambda: _suptitle(fig), ""),
        "png": _attempt(notes, "render PNG", lambda: _png(fig, dpi), b""),
        "truncated": budget.truncated,
        "notes": notes,
    }


def open_figures_data(
    *,
    exclude: Collection[int] = (),
    dpi: float = DEFAULT_DPI,
    max_points: int = DEFAULT_MAX_POINTS,
) -> list[dict]:
    """Data of every open pyplot figure whose number is not in ``exclude``, by number.

    With ``exclude=open_figure_numbers()`` taken before a call, this gives the
    figures the call created.
    """
    excluded = set(exclude)
    numbers = [n for n in plt.get_fignums() if n not in excluded]
    if not numbers:
        return []
    current = plt.gcf()
    try:
        figures = [plt.figure(n) for n in numbers]
    finally:
        plt.figure(current)  # leave the student's current figure as it was
    data = []
    for n, fig in zip(numbers, figures):
        try:
            data.append(figure_to_data(fig, dpi=dpi, max_points=max_points))
        except Exception as exc:  # a figure_to_data bug must not hide the other figures
            data.append(_empty_figure(f"figure {n} could not be read: {_describe(exc)}"))
    return data


#: The name :mod:`autograder.worker.loop` uses.
figures_data = open_figures_data


def open_figure_numbers() -> list[int]:
    """Numbers of the open pyplot figures."""
    return list(plt.get_fignums())


def close_all() -> None:
    """Close every pyplot figure."""
    plt.close("all")


# --------------------------------------------------------------------------
# per axes


def _axes_data(ax: Axes, budget: _Budget, notes: list[str], where: str) -> dict:
    def field(name: str, fn: Callable[[], Any], default: Any) -> Any:
        return _attempt(notes, f"{where}: {name}", fn, default)

    def each(kind: str, artists: Callable[[], Any], read: Callable[[Any], Any]) -> list:
        found = field(f"{kind}s", lambda: list(artists()), [])
        return _each(notes, f"{where}: {kind}", found, read)

    return {
        "lines": each("line", ax.get_lines, lambda a: _line_data(a, budget)),
        "collections": each(
            "collection", lambda: ax.collections, lambda a: _collection_data(a, ax, budget)
        ),
        "patches": each("patch", lambda: ax.patches, lambda a: _patch_data(a, ax, budget)),
        "images": each("image", lambda: ax.images, _image_data),
        "texts": each("text", lambda: ax.texts, lambda a: _text(a.get_text())),
        "xlim": field("xlim", lambda: [float(v) for v in ax.get_xlim()], [math.nan, math.nan]),
        "ylim": field("ylim", lambda: [float(v) for v in ax.get_ylim()], [math.nan, math.nan]),
        "xlabel": field("xlabel", lambda: _text(ax.get_xlabel()), ""),
        "ylabel": field("ylabel", lambda: _text(ax.get_ylabel()), ""),
        "title": field("title", lambda: _text(ax.get_title()), ""),
        "aspect": field("aspect", lambda: _aspect(ax.get_aspect()), "auto"),
        "legend": field("legend", lambda: _legend_labels(ax), []),
    }


def _line_data(line: Any, budget: _Budget) -> dict:
    x = _float_array(line.get_xdata(), "x")
    y = _float_array(line.get_ydata(), "y")
    k = budget.take(min(len(x), len(y)))
    return {
        "x": x[:k],
        "y": y[:k],
        "label": _text(line.get_label()),
        "color": to_hex(line.get_color()),
        "linestyle": _text(line.get_linestyle()),
        "marker": _text(line.get_marker()),
    }


def _collection_data(coll: Any, ax: Axes, budget: _Budget) -> dict:
    offsets = _offsets(coll, ax)
    offsets = offsets[: budget.take(len(offsets))]
    segments = _segments(coll, ax, budget)
    values = coll.get_array()
    array = None
    if values is not None:
        array = _float_array(values, "array", ravel=False)
        k = budget.take(array.size)
        if k < array.size:
            array = array.ravel()[:k]
    return {"kind": type(coll).__name__, "offsets": offsets, "segments": segments, "array": array}


def _offsets(coll: Any, ax: Axes) -> np.ndarray:
    """The collection's offsets in data coordinates; (0, 2) if they are not data
    (contours, polygons and meshes keep the unused default offset (0, 0))."""
    to_data = _to_data_transform(coll.get_offset_transform(), ax)
    if to_data is None:
        return np.empty((0, 2))
    offsets = _points(coll.get_offsets())
    if to_data is _IDENTITY:
        return offsets
    return np.array(to_data.transform(offsets), dtype=np.float64)


def _segments(coll: Any, ax: Axes, budget: _Budget) -> list[np.ndarray]:
    """Vertices of the collection's paths in data coordinates, one array per sub-path.

    Paths not drawn in data coordinates (scatter markers, sized in points)
    give no segments: their positions are the offsets.
    """
    to_data = _to_data_transform(coll.get_transform(), ax)
    if to_data is None:
        return []
    if type(coll).__name__ == "QuadMesh":  # its paths are made on demand: count before making them
        ny, nx = np.shape(coll.get_coordinates())[:2]
        if 5 * max(ny - 1, 0) * max(nx - 1, 0) > budget.left:
            budget.truncated = True
            return []
    segments = []
    for path in coll.get_paths():
        for piece in _subpaths(path):
            vertices = piece if to_data is _IDENTITY else to_data.transform(piece)
            k = budget.take(len(vertices))
            segments.append(np.array(vertices[:k], dtype=np.float64))
            if k < len(vertices):
                return segments
    return segments


def _patch_data(patch: Any, ax: Axes, budget: _Budget) -> dict:
    vertices = _points(patch.get_path().vertices)
    vertices = patch.get_patch_transform().transform(vertices)
    to_data = _to_data_transform(patch.get_data_transform(), ax)
    if to_data is None:
        raise _Skip("it is not drawn in data coordinates")
    if to_data is not _IDENTITY:
        vertices = to_data.transform(vertices)
    vertices = np.array(vertices, dtype=np.float64)
    return {"kind": type(patch).__name__, "vertices": vertices[: budget.take(len(vertices))]}


def _image_data(image: Any) -> dict:
    return {
        "shape": [int(n) for n in np.shape(image.get_array())],
        "extent": [float(v) for v in image.get_extent()],
    }


def _to_data_transform(transform: Any, ax: Axes) -> Any:
    """``_IDENTITY`` if ``transform`` is the axes' data transform, a transform to data
    coordinates if it ends in it, else None."""
    if transform is ax.transData or transform == ax.transData:
        return _IDENTITY
    if transform.contains_branch(ax.transData):
        return transform - ax.transData
    return None


def _subpaths(path: Path) -> list[np.ndarray]:
    """A path's vertices split at MOVETO, without the CLOSEPOLY/STOP placeholders."""
    vertices = _points(path.vertices)
    codes = path.codes
    if codes is None:
        return [vertices] if len(vertices) else []
    codes = np.asarray(codes)
    starts = np.flatnonzero(codes == Path.MOVETO)
    starts = starts[starts > 0]
    pieces = []
    for v, c in zip(np.split(vertices, starts), np.split(codes, starts)):
        v = v[~np.isin(c, _SKIP_CODES)]
        if len(v):
            pieces.append(v)
    return pieces


# --------------------------------------------------------------------------
# small readers


def _float_array(data: Any, name: str, *, ravel: bool = True) -> np.ndarray:
    """``data`` as a fresh float64 base ndarray (masked values as NaN), or _Skip."""
    if isinstance(data, np.ma.MaskedArray):
        if data.dtype.kind not in "biuf":
            raise _Skip(f"{name} data of dtype {data.dtype} is not numeric")
        arr = np.ma.filled(data.astype(np.float64), np.nan)
    else:
        arr = np.asarray(data)
        if arr.dtype.kind not in "biufO":
            raise _Skip(f"{name} data of dtype {arr.dtype} is not numeric")
        try:
            arr = np.array(arr, dtype=np.float64, order="C")
        except (TypeError, ValueError):
            raise _Skip(f"{name} data is not numeric (dates or strings?)") from None
    return arr.ravel() if ravel else arr


def _points(data: Any) -> np.ndarray:
    """``data`` as a (k, 2) float64 array."""
    arr = _float_array(data, "point", ravel=False)
    return arr.reshape(-1, 2)


def _aspect(aspect: Any) -> str | float:
    if isinstance(aspect, str):
        return aspect if aspect in ("auto", "equal") else _text(aspect)
    value = float(aspect)
    return "equal" if value == 1.0 else value


def _legend_labels(ax: Axes) -> list[str]:
    legend = ax.get_legend()
    return [] if legend is None else [_text(t.get_text()) for t in legend.get_texts()]


def _suptitle(fig: Figure) -> str:
    if hasattr(fig, "get_suptitle"):  # matplotlib >= 3.8
        return _text(fig.get_suptitle())
    return _text(fig._suptitle.get_text()) if fig._suptitle is not None else ""


def _png(fig: Figure, dpi: float) -> bytes:
    width, height = fig.get_size_inches()
    pixels = width * height * dpi * dpi
    if pixels > MAX_PNG_PIXELS:
        dpi = dpi * math.sqrt(MAX_PNG_PIXELS / pixels)
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=dpi)
    return out.getvalue()


def _text(value: Any) -> str:
    return (value if type(value) is str else str(value))[:MAX_TEXT_CHARS]


def _describe(exc: BaseException) -> str:
    if isinstance(exc, _Skip):
        return str(exc)
    try:
        return f"{type(exc).__name__}: {exc}"[:200]
    except Exception:
        return type(exc).__name__


def _attempt(notes: list[str], what: str, fn: Callable[[], Any], default: Any) -> Any:
    try:
        return fn()
    except Exception as exc:
        notes.append(f"{what} failed: {_describe(exc)}")
        return default


def _each(notes: list[str], what: str, artists: list, read: Callable[[Any], Any]) -> list:
    """``read`` of each artist; one that fails is skipped with a note."""
    out = []
    for i, artist in enumerate(artists):
        try:
            out.append(read(artist))
        except Exception as exc:
            notes.append(f"{what} {i} skipped: {_describe(exc)}")
    return out


def _empty_figure(note: str) -> dict:
    return {
        "$t": "figure",
        "axes": [],
        "suptitle": "",
        "png": b"",
        "truncated": False,
        "notes": [note],
    }
