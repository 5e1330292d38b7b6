"""Tests of the figures of reference: each figure draws onto the given axes only."""

from __future__ import annotations

import io
import re

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402  (after selecting the backend)
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.artist import Artist  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

import reference._plotting as plotting  # noqa: E402
from reference import bezier  # noqa: E402
from reference import car  # noqa: E402
from reference import convex_hull  # noqa: E402
from reference import (  # noqa: E402
    chebyshev_nodes,
    equispaced_nodes,
    equispaced_weights,
)
from reference import (  # noqa: E402
    plot_car,
    plot_de_casteljau,
    plot_interpolant,
    plot_points_and_hull,
    plot_spline,
    tplot,
)

POINTS = np.random.default_rng(20240101).normal(size=(12, 2))
QUAD = np.array([[0.0, 0.0], [1.0, 1.0], [1.2, 0.4]])  # the lecture's quad_demo
CUBIC = np.array([[0.0, 0.0], [4.0, 1.0], [9.0, 1.0], [3.0, 4.0]])  # cubic_demo
SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]])
SQUARE_TRIANGLES = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])


def runge(x):
    return 1.0 / (1.0 + 16.0 * x**2)


@pytest.fixture
def ax():
    """Axes on a figure that pyplot does not know about; checks none is created."""
    before = plt.get_fignums()
    axes = Figure().add_subplot()
    yield axes
    assert plt.get_fignums() == before, "a plotting function created a pyplot figure"
    buffer = io.BytesIO()
    axes.figure.savefig(buffer, format="png")  # everything drawn can be rendered
    assert buffer.getvalue()[:8] == b"\x89PNG\r\n\x1a\n"


def assert_drawn_on(artists, ax):
    assert isinstance(artists, list) and artists
    for artist in artists:
        assert isinstance(artist, Artist)
        assert artist.axes is ax


def test_points_and_hull(ax):
    artists = plot_points_and_hull(ax, POINTS)
    assert_drawn_on(artists, ax)
    dots, polygon = artists
    np.testing.assert_array_equal(dots.get_xydata(), POINTS)
    hull = convex_hull(POINTS)
    np.testing.assert_array_equal(polygon.get_xydata(), POINTS[np.append(hull, hull[0])])
    assert ax.get_aspect() == 1.0


def test_points_and_given_hull(ax):
    polygon = plot_points_and_hull(ax, SQUARE, hull=[0, 1, 2, 3])[1]
    np.testing.assert_array_equal(polygon.get_xydata(), SQUARE[[0, 1, 2, 3, 0]])


@pytest.mark.parametrize("ctrl, t", [(QUAD, 0.4), (CUBIC, 0.7)])
def test_de_casteljau(ax, ctrl, t):
    artists = plot_de_casteljau(ax, ctrl, t, num=60)
    assert_drawn_on(artists, ax)
    n = ctrl.shape[0] - 1
    assert len(artists) == 2 + 2 * n - 1  # curve, polygon, each level's segments + points
    curve, polygon = artists[0], artists[1]
    np.testing.assert_allclose(curve.get_xydata(), bezier(ctrl, np.linspace(0, 1, 60)))
    np.testing.assert_array_equal(polygon.get_xydata(), ctrl)
    np.testing.assert_allclose(artists[-1].get_xydata()[0], bezier(ctrl, t), atol=1e-14)
    first_level = (1 - t) * ctrl[:-1] + t * ctrl[1:]
    np.testing.assert_allclose(artists[3].get_xydata(), first_level, atol=1e-14)


def test_interpolant(ax):
    nodes = equispaced_nodes(15)
    artists = plot_interpolant(ax, runge, nodes, equispaced_weights(15), num=101, label="equispaced")
    assert_drawn_on(artists, ax)
    exact, interp, marks = artists[:3]
    t = np.linspace(-1, 1, 101)
    np.testing.assert_allclose(exact.get_xydata()[:, 1], runge(t))
    np.testing.assert_allclose(marks.get_xydata(), np.column_stack([nodes, runge(nodes)]))
    assert interp.get_label() == "equispaced"
    assert interp.get_ydata().max() > 1.1  # overshoots max f = 1: Runge's phenomenon
    assert ax.get_legend() is artists[-1]


def test_interpolant_default_weights(ax):
    artists = plot_interpolant(ax, runge, chebyshev_nodes(30))
    interp = artists[1].get_xydata()
    assert np.abs(interp[:, 1] - runge(interp[:, 0])).max() < 1e-3


def test_spline(ax):
    stroke = car()[0]
    artists = plot_spline(ax, stroke, num=300)
    assert_drawn_on(artists, ax)
    curve, marks = artists
    assert curve.get_xydata().shape == (300, 2)
    np.testing.assert_array_equal(marks.get_xydata(), stroke)
    np.testing.assert_allclose(curve.get_xydata()[[0, -1]], stroke[[0, -1]], atol=1e-12)


def test_spline_options(ax):
    theta = np.linspace(0, 2 * np.pi, 9)
    ring = np.column_stack([np.cos(theta), np.sin(theta)])
    ring[-1] = ring[0]
    artists = plot_spline(ax, ring, bc_type="periodic", parametrization="centripetal")
    assert_drawn_on(artists, ax)


def test_car(ax):
    artists = plot_car(ax)
    assert_drawn_on(artists, ax)
    assert len(artists) == len(car())
    assert all(isinstance(a, Line2D) for a in artists)
    assert ax.get_aspect() == 1.0


def test_car_with_given_strokes(ax):
    strokes = [np.array([[0, 0], [1, 1], [2, 0]]), np.array([[0, 2], [1, 3]])]
    artists = plot_car(ax, strokes, num=20)
    assert len(artists) == 2 and artists[0].get_xydata().shape == (20, 2)


def test_tplot_mesh(ax):
    artists = tplot(ax, SQUARE, SQUARE_TRIANGLES)
    assert_drawn_on(artists, ax)
    assert len(artists[0].get_paths()) == len(SQUARE_TRIANGLES)
    assert ax.get_aspect() == 1.0


def test_tplot_contours(ax):
    u = np.exp(-(SQUARE**2).sum(axis=1))
    artists = tplot(ax, SQUARE, SQUARE_TRIANGLES, u=u)
    assert_drawn_on(artists, ax)
    assert len(artists[0].levels) > 5


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: plot_points_and_hull(None, POINTS), "`ax` must be a matplotlib Axes; got NoneType."),
        (lambda: plot_points_and_hull(plt, POINTS), "`ax` must be a matplotlib Axes; got module."),
        (lambda a: plot_points_and_hull(a, POINTS[:, :1]), "`points` must have shape (n, 2)"),
        (lambda a: plot_points_and_hull(a, POINTS, hull=[0, 12]), "`hull` must index the 12 points"),
        (lambda a: plot_points_and_hull(a, POINTS, hull=[0.0, 1.0]), "`hull` must hold integer"),
        (lambda a: plot_points_and_hull(a, POINTS, hull=[]), "`hull` must hold at least one"),
        (lambda a: plot_de_casteljau(a, QUAD, 1.5), "`t` must be a single number in [0, 1]"),
        (lambda a: plot_de_casteljau(a, QUAD, [0.1, 0.2]), "`t` must be a single number"),
        (lambda a: plot_de_casteljau(a, QUAD[:1], 0.5), "`ctrl` must hold at least 2 point(s)"),
        (lambda a: plot_de_casteljau(a, QUAD, 0.5, num=1), "`num` must be >= 2; got 1."),
        (lambda a: plot_interpolant(a, 3.0, [0.0, 1.0]), "`f` must be callable; got float."),
        (lambda a: plot_interpolant(a, lambda x: 1.0, [0.0, 1.0]), "`f` must be vectorised"),
        (lambda a: plot_interpolant(a, lambda x: np.where(x > 0.5, np.inf, x), [0.0, 1.0]), "`f` must return finite values"),
        (lambda a: plot_interpolant(a, runge, []), "`nodes` must hold at least one node"),
        (lambda a: plot_interpolant(a, runge, [0.0, 1.0], label=3), "`label` must be a string"),
        (lambda a: plot_spline(a, [[0, 0], [0, 0], [1, 1]]), "`points[1]` repeats `points[0]`"),
        (lambda a: plot_car(a, np.zeros((3, 2))), "`strokes` must be a sequence of (m, 2) arrays"),
        (lambda a: plot_car(a, []), "`strokes` must hold at least one stroke"),
        (lambda a: plot_car(a, [np.zeros((3, 2))]), "`strokes[0]`: `points[1]` repeats"),
        (lambda a: plot_car(a, [np.ones((3, 3))]), "`strokes[0]` must have shape (n, 2)"),
        (lambda a: tplot(a, SQUARE, [[0, 1, 5]]), "`triangles` must index the 5 points"),
        (lambda a: tplot(a, SQUARE, [[0, 1]]), "`triangles` must have shape (m, 3)"),
        (lambda a: tplot(a, SQUARE, [0, 1, 2]), "`triangles` must be 2-dimensional"),
        (lambda a: tplot(a, SQUARE, SQUARE_TRIANGLES, u=[1.0, 2.0]), "`u` must hold one value per point"),
    ],
)
def test_bad_input_is_rejected(ax, call, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        call(ax) if call.__code__.co_argcount else call()
    assert not ax.lines and not ax.collections  # nothing drawn before validation
