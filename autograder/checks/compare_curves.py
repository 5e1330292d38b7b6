"""Compare drawings as point sets: for checks that grade a student's figure.

A student can draw the same curve in many ways: one ``ax.plot`` per stroke,
one long line with NaN breaks, a scatter of dense samples, a
``LineCollection``, polygons. :func:`curve_points` turns figure data (the plain
dict a student's ``Figure`` becomes at the boundary, see ``docs/design.md``)
into one ``(k, 2)`` array of drawn points in data coordinates, whatever drew
them. Two drawings are then compared by their directed Hausdorff distances
(:func:`hausdorff`, :func:`relative_curve_distance`): the *forward* distance
(from the reference to the student) is large when part of the reference is
missing, the *backward* one (from the student to the reference) when the
student drew something extra.

:func:`render_side_by_side` makes the picture a check attaches to its result:
the student's drawing on the left, the reference (drawn by a function the
assignment's checks give) on the right. Course content (the car, its splines)
lives in the assignments, never here.

This module runs on the trusted side only.
"""

from __future__ import annotations

import io
import math
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "CurveDistance",
    "curve_pieces",
    "curve_points",
    "decode_png",
    "hausdorff",
    "relative_curve_distance",
    "render_side_by_side",
]

#: Line styles that draw no line between the points (markers only).
_NO_LINE = frozenset({"None", "none", "", " "})

#: Most points :func:`curve_points` makes by densifying; beyond it each
#: segment gets fewer samples (a line of that many points is dense already).
_MAX_DENSE_POINTS = 2_000_000

#: Size of the side-by-side picture: inches and dots per inch.
_SIDE_BY_SIDE_INCHES = (10.0, 4.0)
_SIDE_BY_SIDE_DPI = 80

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

#: Largest picture (width x height) decoded from a student's PNG: 4 times a
#: full-HD screen, far beyond any figure a notebook draws at normal dpi.
MAX_PNG_PIXELS = 4 * 1920 * 1080


# ---------------------------------------------------------------------------
# figure data -> points
# ---------------------------------------------------------------------------


def _as_xy(data: Any) -> NDArray[np.float64]:
    """``data`` as a float ``(k, 2)`` array; an empty ``(0, 2)`` array if it is not one."""
    try:
        arr = np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError):
        return np.empty((0, 2))
    if arr.size == 0 or arr.ndim != 2 or arr.shape[1] != 2:
        return np.empty((0, 2))
    return arr


def _as_flat(data: Any) -> NDArray[np.float64]:
    """``data`` as a flat float array; an empty one if it holds anything but numbers."""
    try:
        return np.ravel(np.asarray(data if data is not None else [], dtype=np.float64))
    except (TypeError, ValueError):
        return np.empty(0)


def _densify(polyline: NDArray[np.float64], samples: int) -> NDArray[np.float64]:
    """The finite points of ``polyline`` plus ``samples - 1`` points inside each segment.

    A segment with a non-finite end is a break in the line (matplotlib draws
    nothing there) and gets no points; non-finite points are dropped.
    """
    finite = np.all(np.isfinite(polyline), axis=1)
    points = polyline[finite]
    if samples < 2 or len(polyline) < 2:
        return points
    a, b = polyline[:-1], polyline[1:]
    drawn = finite[:-1] & finite[1:]
    a, b = a[drawn], b[drawn]
    t = np.arange(1, samples, dtype=np.float64) / samples
    inner = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    return np.concatenate([points, inner.reshape(-1, 2)])


def _axes_pieces(axes: Mapping[str, Any]) -> tuple[list[NDArray[np.float64]],
                                                    list[NDArray[np.float64]]]:
    """The polylines (drawn between points) and point sets (markers only) of one axes."""
    polylines: list[NDArray[np.float64]] = []
    scattered: list[NDArray[np.float64]] = []
    for line in axes.get("lines", []) or []:
        x, y = _as_flat(line.get("x")), _as_flat(line.get("y"))
        k = min(len(x), len(y))
        xy = np.column_stack([x[:k], y[:k]])
        if line.get("linestyle", "-") in _NO_LINE:
            scattered.append(xy)
        else:
            polylines.append(xy)
    for coll in axes.get("collections", []) or []:
        offsets = coll.get("offsets")
        if offsets is not None:
            scattered.append(_as_xy(offsets))
        for segment in coll.get("segments", []) or []:
            polylines.append(_as_xy(segment))
    for patch in axes.get("patches", []) or []:
        polylines.append(_as_xy(patch.get("vertices")))
    return polylines, scattered


def _figure_pieces(figure: Mapping[str, Any]) -> tuple[list[NDArray[np.float64]],
                                                      list[NDArray[np.float64]]]:
    """The polylines and point sets of every axes of ``figure`` (checked to be figure data)."""
    if not isinstance(figure, Mapping) or not isinstance(figure.get("axes"), list):
        raise ValueError("`figure` must be figure data: a dict with an 'axes' list.")
    polylines: list[NDArray[np.float64]] = []
    scattered: list[NDArray[np.float64]] = []
    for axes in figure["axes"]:
        if isinstance(axes, Mapping):
            lines, points = _axes_pieces(axes)
            polylines += lines
            scattered += points
    return polylines, scattered


def curve_pieces(figure: Mapping[str, Any]) -> list[NDArray[np.float64]]:
    """Each line, point set, collection path and patch outline of a figure, one by one.

    Parameters
    ----------
    figure : dict
        Figure data as decoded at the boundary (see :func:`curve_points`).

    Returns
    -------
    list of ndarray, shape (k, 2)
        The finite points of each drawn piece, in data coordinates and drawing
        order (a line with NaN breaks is one piece); pieces may be empty.
        For checks that look for one curve among several (``curve_points``
        merges them all).

    Raises
    ------
    ValueError
        If ``figure`` is not a mapping with an ``"axes"`` list.
    """
    polylines, scattered = _figure_pieces(figure)
    return [p[np.all(np.isfinite(p), axis=1)] for p in polylines + scattered]


def curve_points(figure: Mapping[str, Any], *,
                 samples_per_segment: int = 20) -> NDArray[np.float64]:
    """Every point a figure draws, in data coordinates, as one ``(k, 2)`` array.

    Parameters
    ----------
    figure : dict
        Figure data as decoded at the boundary: ``{"axes": [{"lines": ...,
        "collections": ..., "patches": ...}, ...], ...}``.  Every axes is read.
    samples_per_segment : int, optional
        Each straight segment of a drawn line is cut into this many pieces, so
        that a polyline of a few points still covers its segments.  Lowered
        automatically when the figure already has very many points.

    Returns
    -------
    ndarray, shape (k, 2)
        The points of ``Line2D`` data (densified along the segments unless the
        line draws markers only), collection offsets (scatter), collection
        paths in data coordinates (``LineCollection`` segments, polygons),
        and patch outlines.  Non-finite points are left out; ``k`` may be 0.

    Raises
    ------
    ValueError
        If ``figure`` is not a mapping with an ``"axes"`` list, or
        ``samples_per_segment`` is not a positive integer.
    """
    if isinstance(samples_per_segment, bool) or not isinstance(samples_per_segment, int) \
            or samples_per_segment < 1:
        raise ValueError(
            f"`samples_per_segment` must be a positive integer; got {samples_per_segment!r}.")
    polylines, scattered = _figure_pieces(figure)
    vertices = sum(len(p) for p in polylines)
    samples = max(1, min(samples_per_segment, _MAX_DENSE_POINTS // max(vertices, 1)))
    parts = [_densify(p, samples) for p in polylines]
    parts += [p[np.all(np.isfinite(p), axis=1)] for p in scattered]
    parts = [p for p in parts if len(p)]
    return np.concatenate(parts) if parts else np.empty((0, 2))


# ---------------------------------------------------------------------------
# distances
# ---------------------------------------------------------------------------


def _directed(a: NDArray[np.float64], b: NDArray[np.float64]) -> tuple[float, int]:
    """``max over a of (distance to the nearest point of b)`` and the index in ``a``."""
    if len(a) == 0:
        return 0.0, -1
    if len(b) == 0:
        return math.inf, 0
    # Imported here, not with the module: every check module imports this one through
    # autograder.checks, and scipy.spatial costs 0.24 s at each grader's start while
    # only the checks that compare curves use it.
    from scipy.spatial import cKDTree

    gaps, _ = cKDTree(b).query(a)
    k = int(np.argmax(gaps))
    return float(gaps[k]), k


def _clean(points: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(points, dtype=np.float64)
    if arr.size == 0:
        return np.empty((0, 2))
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"`{name}` must have shape (k, 2); got {arr.shape}.")
    return arr[np.all(np.isfinite(arr), axis=1)]


def hausdorff(a: ArrayLike, b: ArrayLike) -> tuple[float, float]:
    """The two directed Hausdorff distances between point sets ``a`` and ``b``.

    Returns
    -------
    (float, float)
        ``h(a, b) = max_{p in a} min_{q in b} |p - q|`` (how far ``a`` strays
        from ``b``) and ``h(b, a)``.  The Hausdorff distance is their maximum.
        An empty set is at distance 0 from anything, and anything non-empty
        is at distance ``inf`` from an empty set.
    """
    a, b = _clean(a, "a"), _clean(b, "b")
    return _directed(a, b)[0], _directed(b, a)[0]


@dataclass(frozen=True)
class CurveDistance:
    """How far a student's drawing is from the reference drawing.

    Attributes
    ----------
    forward : float
        Largest distance from a reference point to the student's drawing:
        large when a part of the reference is *missing*.
    backward : float
        Largest distance from a student point to the reference: large when the
        student drew *extra* parts.
    scale : float
        Diagonal of the reference's bounding box (the unit of the relative values).
    forward_at, backward_at : tuple of float, or None
        Where each largest distance occurs (the reference point farthest from
        the student's drawing, the student point farthest from the reference).
    """

    forward: float
    backward: float
    scale: float
    forward_at: tuple[float, float] | None = None
    backward_at: tuple[float, float] | None = None

    @property
    def forward_relative(self) -> float:
        """``forward / scale``."""
        return self.forward / self.scale

    @property
    def backward_relative(self) -> float:
        """``backward / scale``."""
        return self.backward / self.scale

    @property
    def worst(self) -> float:
        """The larger relative distance: the relative Hausdorff distance."""
        return max(self.forward_relative, self.backward_relative)

    def gaps(self, what: str, allowed: float) -> str:
        """What the drawing misses or adds beyond ``allowed`` (relative), for a message.

        ``what`` names the reference ("car"). Empty when neither distance
        exceeds ``allowed``; otherwise where the farthest missing reference
        point and the farthest extra point lie, and how far they are.
        """
        parts = []
        if self.forward_relative > allowed:
            if self.forward_at is None:
                parts.append(f"the {what} is missing from your drawing: it has no curves")
            else:
                x, y = self.forward_at
                parts.append(f"parts of the {what} are missing from your drawing (the farthest "
                             f"reference point is {self.forward:.2g} units from any of your "
                             f"curves, near ({x:.1f}, {y:.1f}))")
        if self.backward_relative > allowed and self.backward_at is not None:
            x, y = self.backward_at
            parts.append(f"your drawing has extra parts (e.g. near ({x:.1f}, {y:.1f}), "
                         f"{self.backward:.2g} units from the reference)")
        return "; ".join(parts)

    def to_dict(self) -> dict[str, Any]:
        """The fields and ``worst`` as plain data."""
        return {"forward": self.forward, "backward": self.backward, "scale": self.scale,
                "forward_at": self.forward_at, "backward_at": self.backward_at,
                "worst": self.worst}


def relative_curve_distance(student_pts: ArrayLike, reference_pts: ArrayLike) -> CurveDistance:
    """Directed Hausdorff distances between a drawing and the reference, with their scale.

    Parameters
    ----------
    student_pts, reference_pts : array_like, shape (k, 2)
        Points of the two drawings (see :func:`curve_points`; the reference
        drawing's points come from the assignment's checks).  Non-finite points are ignored.

    Returns
    -------
    CurveDistance
        ``forward`` (reference -> student), ``backward`` (student ->
        reference), the reference's bounding-box diagonal as ``scale``, and
        where the two maxima occur.  With no student points ``forward`` is
        ``inf``.

    Raises
    ------
    ValueError
        If the reference has no finite point or all its points coincide.
    """
    student = _clean(student_pts, "student_pts")
    reference = _clean(reference_pts, "reference_pts")
    if len(reference) == 0:
        raise ValueError("`reference_pts` must hold at least one finite point.")
    scale = float(np.hypot(*(reference.max(axis=0) - reference.min(axis=0))))
    if scale == 0.0:
        raise ValueError("`reference_pts` must not all be the same point.")
    forward, k = _directed(reference, student)
    backward, j = _directed(student, reference)
    return CurveDistance(
        forward=forward, backward=backward, scale=scale,
        forward_at=tuple(float(v) for v in reference[k]) if len(student) else None,
        backward_at=tuple(float(v) for v in student[j]) if len(student) else None,
    )


# ---------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------


def decode_png(png: Any, *, max_pixels: int = MAX_PNG_PIXELS) -> NDArray[Any] | None:
    """The image in ``png`` (bytes or a uint8 array of them), or None if it is not a usable PNG.

    The size in the PNG header is read first: a picture larger than
    ``max_pixels`` (a small file can claim 13,000 x 13,000 pixels) is never
    decompressed, so a student's figure cannot exhaust the grader's memory.
    """
    import matplotlib.image as mpimg

    if isinstance(png, np.ndarray) and png.dtype == np.uint8:
        png = png.tobytes()
    if not isinstance(png, (bytes, bytearray, memoryview)):
        return None
    data = bytes(png)
    if not data.startswith(_PNG_SIGNATURE) or len(data) < 24 or data[12:16] != b"IHDR":
        return None
    width, height = struct.unpack(">II", data[16:24])
    if width * height > max_pixels:
        return None
    try:
        return mpimg.imread(io.BytesIO(data), format="png")
    except Exception:  # a truncated or corrupt PNG from the worker: show a placeholder
        return None


def render_side_by_side(student_png: bytes | None, draw_reference: Callable[[Any], object], *,
                        title: str = "your drawing (left) and the reference (right)",
                        left_title: str = "your drawing",
                        right_title: str = "reference") -> bytes:
    """A PNG with the student's picture on the left and the reference drawing on the right.

    Parameters
    ----------
    student_png : bytes or None
        The PNG of the student's figure (``figure_data["png"]``).  If it is
        missing, too large or cannot be decoded, the left panel says so.
    draw_reference : callable
        ``draw_reference(ax)`` draws the reference on the right-hand
        ``Axes``.  What the reference is (a car, a curve, a mesh) belongs to
        the assignment's checks, not to the engine.
    title, left_title, right_title : str, optional
        The picture's title and the two panels' titles.

    Returns
    -------
    bytes
        A PNG of about 800 x 320 pixels.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=_SIDE_BY_SIDE_INCHES, dpi=_SIDE_BY_SIDE_DPI)
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2)
    image = decode_png(student_png)
    left.set_axis_off()
    if image is None:
        left.text(0.5, 0.5, "no picture of your drawing\n(no figure came back, or it could "
                  "not be rendered)",
                  ha="center", va="center", fontsize=12, transform=left.transAxes)
    else:
        left.imshow(image)
    left.set_title(left_title)
    draw_reference(right)
    right.set_title(right_title)
    right.tick_params(labelsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=_SIDE_BY_SIDE_DPI)
    return out.getvalue()
