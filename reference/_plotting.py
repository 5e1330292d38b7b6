"""The lecture's figures, each drawn onto a given matplotlib ``Axes``.

Every function takes the axes first, draws, and returns the list of artists
it created (lines, collections, legends), so that a check can inspect them and
a notebook can style them.  Nothing here creates a figure, selects a backend
or calls ``plt.show()``.

The figures follow the Julia lecture "Geometry and interpolation": points and
their convex hull, de Casteljau's construction (``quad_demo``/``cubic_demo``),
an interpolant against the exact function (Runge's phenomenon), a spline
through points, the car, and ``tplot`` for triangle meshes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from numpy.typing import ArrayLike, NDArray

from reference._validation import (
    as_finite_array,
    as_nonnegative_int,
    as_points,
)
from reference._bezier import bezier, de_casteljau
from reference._data import car
from reference._geometry import convex_hull
from reference._barycentric import barycentric_interpolate
from reference._splines import parametric_spline

__all__ = [
    "plot_points_and_hull",
    "plot_de_casteljau",
    "plot_interpolant",
    "plot_spline",
    "plot_car",
    "tplot",
]

# Colours of the de Casteljau levels 1, 2, ...: red then green as in the lecture.
_LEVEL_COLOURS = ("tab:red", "tab:green", "tab:purple", "tab:orange", "tab:cyan", "tab:brown")


def _check_ax(ax: Any) -> Axes:
    if not isinstance(ax, Axes):
        raise ValueError(f"`ax` must be a matplotlib Axes; got {type(ax).__name__}.")
    return ax


def _as_indices(value: ArrayLike, name: str, n: int, *, ndim: int) -> NDArray[np.intp]:
    """Integer array of indices into ``n`` points, with ``ndim`` dimensions."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu" and not (arr.size == 0 and arr.dtype.kind == "f"):
        raise ValueError(f"`{name}` must hold integer indices; got dtype {arr.dtype}.")
    if arr.ndim != ndim:
        raise ValueError(f"`{name}` must be {ndim}-dimensional; got shape {arr.shape}.")
    arr = arr.astype(np.intp)
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise ValueError(
            f"`{name}` must index the {n} points (0 to {n - 1}); got values from "
            f"{arr.min()} to {arr.max()}."
        )
    return arr


def plot_points_and_hull(
    ax: Axes, points: ArrayLike, hull: ArrayLike | None = None
) -> list[Artist]:
    """Draw points as dots and their convex hull as a closed polygon.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    points : array_like, shape (n, 2)
        Finite points, ``n >= 1``.
    hull : array_like of int, shape (h,), optional
        Indices of the hull vertices in order (not repeating the first).
        Default: ``convex_hull(points)``.

    Returns
    -------
    list of Artist
        ``[dots, hull_polygon]`` (two ``Line2D``).

    Raises
    ------
    ValueError
        If ``ax`` is not an ``Axes``, ``points`` is not a finite ``(n, 2)``
        array, or ``hull`` is not a 1-D array of valid indices with ``h >= 1``.

    Notes
    -----
    The lecture's figure after ``convex_hull(p)``: ``plot(p, ".")`` and
    ``plot(p[hull])`` with equal axes and a grid.  The polygon is closed here
    by repeating its first vertex.

    Examples
    --------
    >>> import matplotlib
    >>> from matplotlib.figure import Figure
    >>> from reference import plot_points_and_hull
    >>> ax = Figure().add_subplot()
    >>> dots, polygon = plot_points_and_hull(ax, [[0, 0], [1, 0], [0, 1], [0.2, 0.2]])
    >>> polygon.get_xydata().tolist()
    [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]
    """
    ax = _check_ax(ax)
    pts = as_points(points, "points")
    if hull is None:
        idx = convex_hull(pts)
    else:
        idx = _as_indices(hull, "hull", pts.shape[0], ndim=1)
        if idx.size == 0:
            raise ValueError("`hull` must hold at least one index; got an empty array.")
    ring = pts[np.append(idx, idx[0])]
    (dots,) = ax.plot(pts[:, 0], pts[:, 1], ".", label="points")
    (polygon,) = ax.plot(ring[:, 0], ring[:, 1], "-", label="convex hull")
    ax.set_aspect("equal")
    ax.grid(True)
    return [dots, polygon]


def plot_de_casteljau(ax: Axes, ctrl: ArrayLike, t: float, num: int = 200) -> list[Artist]:
    """Draw a Bezier curve, its control polygon and de Casteljau's construction at ``t``.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    ctrl : array_like, shape (n + 1, 2)
        Control points, ``n >= 1``.
    t : float
        The parameter of the construction, in ``[0, 1]``.
    num : int, optional
        Number of curve points drawn (at least 2).

    Returns
    -------
    list of Artist
        The curve, the control polygon, then for each level ``r = 1..n`` its
        polygon (when it has two or more points) and its points; the last
        artist is the curve point ``B(t)``.

    Raises
    ------
    ValueError
        If ``ax`` is not an ``Axes``, ``ctrl`` is not a finite ``(n + 1, 2)``
        array with ``n >= 1``, ``t`` is not a number in ``[0, 1]``, or ``num``
        is not an integer ``>= 2``.

    Notes
    -----
    Level ``r`` holds ``P_i^{(r)} = (1 - t) P_i^{(r-1)} + t P_{i+1}^{(r-1)}``;
    each of its points lies the fraction ``t`` along a segment of the
    polygon of level ``r - 1``, and the single point of level ``n`` is on the
    curve.  The lecture's ``quad_demo`` (``t = 0.4``) and ``cubic_demo``
    (``t = 0.7``) draw levels in red, then green, as here.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from reference import plot_de_casteljau
    >>> ax = Figure().add_subplot()
    >>> artists = plot_de_casteljau(ax, [[0, 0], [1, 1], [1.2, 0.4]], 0.4)
    >>> len(artists)  # curve, polygon, level 1 (segment + points), level 2 (point)
    5
    """
    ax = _check_ax(ax)
    ctrl = as_points(ctrl, "ctrl", min_points=2)
    t_arr = as_finite_array(t, "t")
    if t_arr.ndim != 0 or not 0.0 <= float(t_arr) <= 1.0:
        raise ValueError(f"`t` must be a single number in [0, 1]; got {t!r}.")
    num = as_nonnegative_int(num, "num", minimum=2)
    curve = bezier(ctrl, np.linspace(0.0, 1.0, num))
    artists: list[Artist] = []
    artists += ax.plot(curve[:, 0], curve[:, 1], "-", color="tab:blue", label="Bezier curve")
    artists += ax.plot(ctrl[:, 0], ctrl[:, 1], "o-", color="k", label="control polygon")
    levels = de_casteljau(ctrl, float(t_arr))
    for r, level in enumerate(levels[1:], start=1):
        colour = _LEVEL_COLOURS[(r - 1) % len(_LEVEL_COLOURS)]
        if level.shape[0] > 1:
            artists += ax.plot(level[:, 0], level[:, 1], "-", color=colour)
        artists += ax.plot(level[:, 0], level[:, 1], "o", color=colour, label=f"level {r}")
    ax.set_aspect("equal")
    return artists


def plot_interpolant(
    ax: Axes,
    f: Callable[[NDArray[np.float64]], ArrayLike],
    nodes: ArrayLike,
    weights: ArrayLike | None = None,
    num: int = 400,
    label: str = "Interp",
) -> list[Artist]:
    """Draw a function, its polynomial interpolant at ``nodes``, and the nodes.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    f : callable
        Vectorised function: ``f(x)`` for a 1-D array ``x`` returns an array of
        the same shape with finite values.
    nodes : array_like, shape (n + 1,)
        Distinct interpolation nodes, ``n >= 0``.
    weights : array_like, shape (n + 1,), optional
        Barycentric weights (e.g. ``equispaced_weights(n)``); default: computed
        from the nodes.
    num : int, optional
        Number of plotting points on ``[min(nodes), max(nodes)]`` (at least 2).
    label : str, optional
        Legend label of the interpolant (the exact function is ``"Exact"``).

    Returns
    -------
    list of Artist
        ``[exact, interpolant, nodes, legend]``.

    Raises
    ------
    ValueError
        If ``ax`` is not an ``Axes``, ``f`` is not callable or does not return
        finite values of the right shape, ``nodes``/``weights`` are invalid
        (see :func:`reference.barycentric_interpolate`), ``num``
        is not an integer ``>= 2`` or ``label`` is not a string.

    Notes
    -----
    The lecture's Runge figure: ``f(x) = 1 / (1 + 16 x^2)`` at 16 equispaced
    nodes on ``[-1, 1]`` gives an interpolant that oscillates near the ends,
    while Chebyshev nodes give a close fit.  The interpolant is evaluated by
    the barycentric formula.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from reference import equispaced_nodes, equispaced_weights
    >>> from reference import plot_interpolant
    >>> ax = Figure().add_subplot()
    >>> runge = lambda x: 1 / (1 + 16 * x**2)
    >>> artists = plot_interpolant(ax, runge, equispaced_nodes(15), equispaced_weights(15))
    >>> [a.get_label() for a in artists[:3]]
    ['Exact', 'Interp', 'nodes']
    """
    ax = _check_ax(ax)
    if not callable(f):
        raise ValueError(f"`f` must be callable; got {type(f).__name__}.")
    x = as_finite_array(nodes, "nodes", ndim=1)
    if x.size == 0:
        raise ValueError("`nodes` must hold at least one node; got an empty array.")
    num = as_nonnegative_int(num, "num", minimum=2)
    if not isinstance(label, str):
        raise ValueError(f"`label` must be a string; got {type(label).__name__}.")
    t = np.linspace(x.min(), x.max(), num)
    exact = _call_vectorised(f, t)
    values = _call_vectorised(f, x)
    interp = barycentric_interpolate(x, values, t, weights=weights)
    artists: list[Artist] = []
    artists += ax.plot(t, exact, "-", label="Exact")
    artists += ax.plot(t, interp, "-", label=label)
    artists += ax.plot(x, values, "o", color="k", markersize=4, label="nodes")
    artists.append(ax.legend())
    return artists


def _call_vectorised(f: Callable[..., ArrayLike], x: NDArray[np.float64]) -> NDArray[np.float64]:
    y = np.asarray(f(x), dtype=np.float64)
    if y.shape != x.shape:
        raise ValueError(
            f"`f` must be vectorised: f(x) for x of shape {x.shape} must return the same "
            f"shape; got {y.shape}."
        )
    if not np.all(np.isfinite(y)):
        raise ValueError("`f` must return finite values at the nodes and plotting points.")
    return y


def plot_spline(
    ax: Axes,
    points: ArrayLike,
    bc_type: Any = "natural",
    parametrization: str = "chord",
    num: int = 200,
) -> list[Artist]:
    """Draw the parametric cubic spline through ``points`` and mark the points.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    points : array_like, shape (m, 2)
        Points to interpolate (see :func:`reference.parametric_spline`).
    bc_type, parametrization
        As in :func:`reference.parametric_spline`.
    num : int, optional
        Number of curve points drawn (at least 2).

    Returns
    -------
    list of Artist
        ``[curve, markers]``.

    Raises
    ------
    ValueError
        If ``ax`` is not an ``Axes``, ``num`` is not an integer ``>= 2``, or
        :func:`~reference.parametric_spline` rejects the input.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from reference import plot_spline
    >>> ax = Figure().add_subplot()
    >>> curve, marks = plot_spline(ax, [[0, 0], [1, 1], [2, 0], [3, 1]], num=50)
    >>> curve.get_xydata().shape
    (50, 2)
    """
    ax = _check_ax(ax)
    pts = as_points(points, "points", min_points=2)
    num = as_nonnegative_int(num, "num", minimum=2)
    curve = parametric_spline(pts, bc_type=bc_type, parametrization=parametrization).sample(num)
    artists: list[Artist] = []
    artists += ax.plot(curve[:, 0], curve[:, 1], "-", label=f"{parametrization} spline")
    artists += ax.plot(pts[:, 0], pts[:, 1], "o", label="points")
    ax.set_aspect("equal")
    return artists


def plot_car(ax: Axes, strokes: Sequence[ArrayLike] | None = None, num: int = 200) -> list[Artist]:
    """Draw every stroke as a parametric natural cubic spline (chord length).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    strokes : sequence of array_like, optional
        Strokes, each an ``(m, 2)`` array with ``m >= 2``; default
        :func:`reference.car`.
    num : int, optional
        Number of points drawn per stroke (at least 2).

    Returns
    -------
    list of Artist
        One ``Line2D`` per stroke, in order.

    Raises
    ------
    ValueError
        If ``ax`` is not an ``Axes``, ``strokes`` is not a non-empty sequence
        of valid strokes (the message names ``strokes[k]``), or ``num`` is not
        an integer ``>= 2``.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from reference import plot_car
    >>> ax = Figure().add_subplot()
    >>> len(plot_car(ax))
    9
    """
    ax = _check_ax(ax)
    if strokes is None:
        strokes = car()
    if isinstance(strokes, np.ndarray) and strokes.ndim == 2:
        raise ValueError("`strokes` must be a sequence of (m, 2) arrays; got a single array.")
    try:
        items = list(strokes)
    except TypeError:
        raise ValueError(
            f"`strokes` must be a sequence of (m, 2) arrays; got {type(strokes).__name__}."
        ) from None
    if not items:
        raise ValueError("`strokes` must hold at least one stroke; got none.")
    num = as_nonnegative_int(num, "num", minimum=2)
    clean = [as_points(s, f"strokes[{k}]", min_points=2) for k, s in enumerate(items)]
    curves = []
    for k, pts in enumerate(clean):
        try:
            curves.append(parametric_spline(pts).sample(num))
        except ValueError as exc:
            raise ValueError(f"`strokes[{k}]`: {exc}") from exc
    artists: list[Artist] = []
    for curve in curves:
        artists += ax.plot(curve[:, 0], curve[:, 1], "-", color="k", linewidth=2,
                           solid_capstyle="round")
    ax.set_aspect("equal")
    return artists


def tplot(
    ax: Axes, points: ArrayLike, triangles: ArrayLike, u: ArrayLike | None = None
) -> list[Artist]:
    """Draw a triangle mesh, or filled colour contours of ``u`` on it.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        Where to draw.
    points : array_like, shape (n, 2)
        Vertices.
    triangles : array_like of int, shape (m, 3)
        Vertex indices of each triangle (0-based), ``m >= 1``.
    u : array_like, shape (n,), optional
        Values at the vertices.  Without ``u`` the triangles are drawn with
        their edges; with ``u``, 20 levels of filled contours.

    Returns
    -------
    list of Artist
        ``[PolyCollection]`` from ``tripcolor`` for the mesh, or
        ``[TriContourSet]`` from ``tricontourf``.

    Raises
    ------
    ValueError
        If ``ax`` is not an ``Axes``, ``points`` is not a finite ``(n, 2)``
        array, ``triangles`` is not an ``(m, 3)`` integer array of valid
        indices with ``m >= 1``, or ``u`` is not a finite array of shape ``(n,)``.

    Notes
    -----
    The lecture's ``tplot(p, t, u)`` (with 1-based Julia indices there):
    ``tripcolor`` with one colour and black edges for the mesh, and
    ``tricontourf(..., u, 20)`` for a function on the mesh; equal axes.

    Examples
    --------
    >>> from matplotlib.figure import Figure
    >>> from reference import tplot
    >>> ax = Figure().add_subplot()
    >>> square = [[0, 0], [1, 0], [1, 1], [0, 1]]
    >>> mesh = tplot(ax, square, [[0, 1, 2], [0, 2, 3]])
    >>> contours = tplot(ax, square, [[0, 1, 2], [0, 2, 3]], u=[0.0, 1.0, 2.0, 1.0])
    >>> len(mesh), len(contours)
    (1, 1)
    """
    ax = _check_ax(ax)
    pts = as_points(points, "points", min_points=3)
    tri = _as_indices(triangles, "triangles", pts.shape[0], ndim=2)
    if tri.shape[1] != 3 or tri.shape[0] == 0:
        raise ValueError(f"`triangles` must have shape (m, 3) with m >= 1; got {tri.shape}.")
    if u is None:
        mesh = ax.tripcolor(
            pts[:, 0], pts[:, 1], tri, facecolors=np.zeros(tri.shape[0]),
            cmap="Set3", edgecolors="k", linewidth=1,
        )
        artists: list[Artist] = [mesh]
    else:
        values = as_finite_array(u, "u", ndim=1)
        if values.shape != (pts.shape[0],):
            raise ValueError(
                f"`u` must hold one value per point, shape ({pts.shape[0]},); got {values.shape}."
            )
        artists = [ax.tricontourf(pts[:, 0], pts[:, 1], tri, values, 20)]
    ax.set_aspect("equal")
    return artists
