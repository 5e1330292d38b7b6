"""Data sets for the assignments: the car drawn with parametric cubic splines.

:func:`car` returns the strokes of a car in side view.  Each stroke is a short
sequence of points; drawing every stroke as a parametric natural cubic spline
with chord-length parameter (:func:`reference.parametric_spline`, the
defaults) gives the picture of :func:`reference.plot_car`.
:func:`save_car` writes the strokes to the ``.npz`` file that assignments ship,
and :func:`load_strokes` reads such a file back.
"""

from __future__ import annotations

import os
import re
import zipfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from reference._validation import as_points

__all__ = ["CAR_STROKE_NAMES", "car", "save_car", "load_strokes"]

CAR_STROKE_NAMES: tuple[str, ...] = (
    "body",
    "underbody",
    "rear_window",
    "front_window",
    "door",
    "rear_wheel",
    "front_wheel",
    "rear_hubcap",
    "front_hubcap",
)
"""Names of the strokes returned by :func:`car`, in the same order."""

# Outline from the rear end of the underbody, round the boot, over the roof and
# bonnet, to the front end of the underbody.  The car faces +x.
_BODY = (
    (1.3, 0.6), (0.7, 0.6), (0.4, 0.64), (0.24, 0.78), (0.16, 1.05), (0.16, 1.45),
    (0.24, 1.8), (0.45, 2.02), (0.9, 2.12), (1.6, 2.16), (2.3, 2.2), (2.85, 2.43),
    (3.35, 2.82), (3.85, 3.12), (4.5, 3.3), (5.3, 3.33), (5.95, 3.24), (6.4, 3.02),
    (6.85, 2.66), (7.3, 2.36), (7.9, 2.22), (8.6, 2.12), (9.2, 1.98), (9.6, 1.8),
    (9.85, 1.52), (9.93, 1.15), (9.86, 0.82), (9.65, 0.64), (9.3, 0.6), (8.6, 0.6),
)
# Sill with the two wheel arches (radius 0.85 about the wheel centres), joined
# to the sill by small fillets so that the curve has no corners.
_UNDERBODY = (
    (1.3, 0.6), (1.406, 0.644), (1.45, 0.75), (1.515, 1.075), (1.699, 1.351),
    (1.975, 1.535), (2.3, 1.6), (2.625, 1.535), (2.901, 1.351), (3.085, 1.075),
    (3.15, 0.75), (3.194, 0.644), (3.3, 0.6), (3.63, 0.6), (3.96, 0.6), (4.29, 0.6),
    (4.62, 0.6), (4.95, 0.6), (5.28, 0.6), (5.61, 0.6), (5.94, 0.6), (6.27, 0.6),
    (6.6, 0.6), (6.706, 0.644), (6.75, 0.75), (6.815, 1.075), (6.999, 1.351),
    (7.275, 1.535), (7.6, 1.6), (7.925, 1.535), (8.201, 1.351), (8.385, 1.075),
    (8.45, 0.75), (8.494, 0.644), (8.6, 0.6),
)
# Closed windows with rounded corners; each starts and ends in the middle of
# its straight lower edge, where the free (natural) ends of the spline meet.
_REAR_WINDOW = (
    (4.16, 2.36), (4.3, 2.36), (4.44, 2.36), (4.58, 2.36), (4.72, 2.36), (4.82, 2.39),
    (4.89, 2.46), (4.92, 2.56), (4.92, 2.66), (4.92, 2.77), (4.92, 2.87), (4.89, 2.97),
    (4.82, 3.04), (4.72, 3.07), (4.61, 3.07), (4.49, 3.07), (4.41, 3.05), (4.31, 3.01),
    (4.2, 2.96), (4.09, 2.92), (3.98, 2.87), (3.85, 2.77), (3.78, 2.71), (3.72, 2.57),
    (3.77, 2.42), (3.92, 2.36), (4.04, 2.36), (4.16, 2.36),
)
_FRONT_WINDOW = (
    (6.03, 2.36), (6.17, 2.36), (6.3, 2.36), (6.45, 2.42), (6.5, 2.57), (6.44, 2.71),
    (6.36, 2.78), (6.28, 2.86), (6.09, 2.95), (5.96, 3.0), (5.84, 3.05), (5.76, 3.07),
    (5.65, 3.07), (5.55, 3.07), (5.44, 3.07), (5.34, 3.04), (5.27, 2.97), (5.24, 2.87),
    (5.24, 2.77), (5.24, 2.66), (5.24, 2.56), (5.27, 2.46), (5.34, 2.39), (5.44, 2.36),
    (5.59, 2.36), (5.74, 2.36), (5.88, 2.36), (6.03, 2.36),
)
# Door: front edge along the windscreen pillar, bottom, rear edge.
_DOOR = (
    (6.7, 2.28), (6.679, 2.049), (6.658, 1.819), (6.636, 1.588), (6.615, 1.357),
    (6.594, 1.127), (6.573, 0.896), (6.524, 0.799), (6.423, 0.76), (6.185, 0.76),
    (5.946, 0.76), (5.707, 0.76), (5.469, 0.76), (5.23, 0.76), (5.124, 0.804),
    (5.08, 0.91), (5.08, 1.138), (5.08, 1.367), (5.08, 1.595), (5.08, 1.823),
    (5.08, 2.052), (5.08, 2.28),
)
_REAR_AXLE = (2.3, 0.75)
_FRONT_AXLE = (7.6, 0.75)
_WHEEL_RADIUS, _WHEEL_SEGMENTS = 0.68, 24
_HUBCAP_RADIUS, _HUBCAP_SEGMENTS = 0.3, 16

_KEY = re.compile(r"stroke_(\d+)")


def _circle(centre: tuple[float, float], radius: float, segments: int) -> NDArray[np.float64]:
    """Closed circle of ``segments + 1`` points, the last exactly equal to the first."""
    angle = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    pts = np.column_stack([centre[0] + radius * np.cos(angle), centre[1] + radius * np.sin(angle)])
    pts[-1] = pts[0]
    return pts


def car() -> list[NDArray[np.float64]]:
    """Return the strokes of a car in side view.

    Returns
    -------
    list of ndarray
        Nine strokes, each a fresh ``(m, 2)`` float array with ``17 <= m <= 35``,
        named in :data:`CAR_STROKE_NAMES`: the body outline (boot, rear window
        line, roof, windscreen, bonnet, bumpers), the underbody with both wheel
        arches, two windows, the door, two wheels and two hub caps.  Windows,
        wheels and hub caps are closed (last point equal to the first).  The
        car spans about ``[0.2, 9.9] x [0.07, 3.33]`` and faces ``+x``.

    Notes
    -----
    The points are spaced so that a parametric natural cubic spline with
    chord-length parameter through each stroke stays within about 1% of the
    stroke's bounding box, without loops or overshoots.  Corners are rounded
    by a few extra points (fillets), because a cubic spline cannot turn a
    sharp corner without overshooting.  Closed strokes start on a straight or
    evenly curved stretch so that the two free ends of a natural spline meet
    almost smoothly.

    Examples
    --------
    >>> from reference import car, CAR_STROKE_NAMES
    >>> strokes = car()
    >>> len(strokes) == len(CAR_STROKE_NAMES)
    True
    >>> dict(zip(CAR_STROKE_NAMES, (s.shape for s in strokes)))["rear_wheel"]
    (25, 2)
    """
    fixed = [_BODY, _UNDERBODY, _REAR_WINDOW, _FRONT_WINDOW, _DOOR]
    strokes = [np.array(points, dtype=np.float64) for points in fixed]
    for centre in (_REAR_AXLE, _FRONT_AXLE):
        strokes.append(_circle(centre, _WHEEL_RADIUS, _WHEEL_SEGMENTS))
    for centre in (_REAR_AXLE, _FRONT_AXLE):
        strokes.append(_circle(centre, _HUBCAP_RADIUS, _HUBCAP_SEGMENTS))
    return strokes


def _as_npz_path(path: str | os.PathLike[str], name: str) -> Path:
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(
            f"`{name}` must be a path (str or os.PathLike); got {type(path).__name__}."
        )
    result = Path(path)
    if result.suffix != ".npz":
        raise ValueError(f"`{name}` must name a .npz file; got {str(result)!r}.")
    return result


def save_car(path: str | os.PathLike[str]) -> Path:
    """Write the strokes of :func:`car` to a ``.npz`` file.

    Parameters
    ----------
    path : str or os.PathLike
        Destination; must end in ``.npz``.  An existing file is replaced.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    ValueError
        If ``path`` is not a path ending in ``.npz``.

    Notes
    -----
    One array per stroke, under the keys ``stroke_00``, ``stroke_01``, ... in
    the order of :data:`CAR_STROKE_NAMES`.  The file holds plain float arrays
    only, so it loads with ``np.load(path, allow_pickle=False)``.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from reference import save_car, load_strokes, car
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     written = save_car(pathlib.Path(tmp) / "car.npz")
    ...     strokes = load_strokes(written)
    >>> all((a == b).all() for a, b in zip(strokes, car()))
    True
    """
    target = _as_npz_path(path, "path")
    arrays = {f"stroke_{k:02d}": stroke for k, stroke in enumerate(car())}
    with open(target, "wb") as handle:  # a file object: np.savez adds no suffix
        np.savez(handle, **arrays)
    return target


def load_strokes(path: str | os.PathLike[str]) -> list[NDArray[np.float64]]:
    """Read strokes written by :func:`save_car` (or any file in that layout).

    Parameters
    ----------
    path : str or os.PathLike
        A ``.npz`` file whose arrays are named ``stroke_00``, ``stroke_01``, ...
        (consecutive, from ``00``), each of shape ``(m, 2)`` with finite values.

    Returns
    -------
    list of ndarray
        The strokes in key order, as ``float64`` arrays.

    Raises
    ------
    ValueError
        If the path does not end in ``.npz``, the file is not a NumPy ``.npz``
        archive, holds an array under another name, the numbering has a gap,
        or a stroke is not a finite ``(m, 2)`` array.
    FileNotFoundError
        If the file does not exist.

    Examples
    --------
    See :func:`save_car`.
    """
    source = _as_npz_path(path, "path")
    try:
        archive = np.load(source, allow_pickle=False)
    except (zipfile.BadZipFile, ValueError, OSError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise ValueError(
            f"`path` must be a NumPy .npz archive; could not read {str(source)!r}."
        ) from exc
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise ValueError(
            f"`path` must be a NumPy .npz archive; {str(source)!r} holds a single array."
        )
    with archive:
        numbered = {}
        for key in archive.files:
            match = _KEY.fullmatch(key)
            if match is None or key != f"stroke_{int(match.group(1)):02d}":
                raise ValueError(
                    f"`path` must hold only arrays named stroke_00, stroke_01, ...; found {key!r}."
                )
            numbered[int(match.group(1))] = key
        if not numbered:
            raise ValueError(f"`path` must hold at least one stroke; {str(source)!r} is empty.")
        missing = sorted(set(range(len(numbered))) - set(numbered))
        if missing:
            raise ValueError(
                "`path` must number its strokes 00, 01, ... without gaps; "
                f"stroke {missing[0]:02d} is missing."
            )
        return [
            as_points(archive[numbered[k]], numbered[k], dim=2).copy()
            for k in range(len(numbered))
        ]
