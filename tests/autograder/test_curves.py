"""Tests of autograder.checks.compare_curves: drawn points from figure data, Hausdorff distances,
and the side-by-side picture. Figure data is built by hand (the format of
docs/design.md), so these tests need no worker."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

from autograder.checks.compare_curves import (
    CurveDistance,
    curve_pieces,
    curve_points,
    decode_png,
    hausdorff,
    relative_curve_distance,
    render_side_by_side,
)

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def line(x, y, linestyle="-", marker="None"):
    return {"x": np.asarray(x, dtype=float), "y": np.asarray(y, dtype=float), "label": "",
            "color": "#000000", "linestyle": linestyle, "marker": marker}


def figure(lines=(), collections=(), patches=(), png=b""):
    return {"axes": [{"lines": list(lines), "collections": list(collections),
                      "patches": list(patches), "images": [], "texts": [],
                      "xlim": [0.0, 1.0], "ylim": [0.0, 1.0], "aspect": "equal"}],
            "png": png}


def circle(num, centre=(0.0, 0.0), radius=1.0):
    t = np.linspace(0.0, 2.0 * np.pi, num)
    return np.column_stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)])


# ---------------------------------------------------------------------------
# curve_points
# ---------------------------------------------------------------------------

def test_line_is_densified_along_its_segments():
    pts = curve_points(figure([line([0, 1, 1], [0, 0, 1])]), samples_per_segment=4)
    # 3 vertices + 3 inner points on each of the 2 segments
    assert pts.shape == (9, 2)
    expected = {(0, 0), (0.25, 0), (0.5, 0), (0.75, 0), (1, 0), (1, 0.25), (1, 0.5),
                (1, 0.75), (1, 1)}
    assert {tuple(p) for p in pts.tolist()} == expected


def test_markers_only_line_is_not_densified():
    pts = curve_points(figure([line([0, 1], [0, 0], linestyle="None", marker="o")]))
    np.testing.assert_array_equal(pts, [[0, 0], [1, 0]])


def test_non_finite_points_break_the_line_and_are_dropped():
    x = [0.0, 1.0, np.nan, 5.0, 6.0]
    y = [0.0, 0.0, np.nan, 0.0, 0.0]
    pts = curve_points(figure([line(x, y)]), samples_per_segment=2)
    assert np.all(np.isfinite(pts))
    # vertices 0, 1, 5, 6 and the midpoints 0.5 and 5.5: nothing between 1 and 5
    np.testing.assert_array_equal(np.sort(pts[:, 0]), [0, 0.5, 1, 5, 5.5, 6])


def test_collections_and_patches():
    scatter = {"kind": "PathCollection", "offsets": np.array([[7.0, 9.0], [8.0, 10.0]]),
               "segments": [], "array": None}
    lines = {"kind": "LineCollection", "offsets": np.empty((0, 2)),
             "segments": [np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([[2.0, 2.0], [3.0, 3.0]])],
             "array": None}
    triangle = {"kind": "Polygon", "vertices": np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0],
                                                         [0.0, 0.0]])}
    pts = curve_points(figure(collections=[scatter, lines], patches=[triangle]),
                       samples_per_segment=2)
    got = {tuple(p) for p in pts.tolist()}
    assert {(7, 9), (8, 10), (0.5, 0.5), (2.5, 2.5), (0.5, 0), (1, 0.5)} <= got
    assert len(pts) == 2 + (2 + 1) * 2 + (4 + 3)


def test_curve_pieces_keeps_each_drawn_piece_apart():
    scatter = {"kind": "PathCollection", "offsets": np.array([[7.0, 9.0], [np.nan, 1.0]]),
               "segments": [np.array([[0.0, 0.0], [1.0, 1.0]])], "array": None}
    pieces = curve_pieces(figure([line([0, 1, np.nan, 3], [0, 1, 2, 3]),
                                  line([5], [5], linestyle="None")], collections=[scatter]))
    # polylines first (the line, the collection's segment), then point sets (markers, offsets)
    assert [p.tolist() for p in pieces] == [[[0, 0], [1, 1], [3, 3]], [[0, 0], [1, 1]],
                                            [[5, 5]], [[7, 9]]]


def test_figure_data_holding_garbage_gives_no_points():
    bad = figure([{"x": "abc", "y": [1, 2]}, {"x": None, "y": None}, line([0, 1], [0, 1])])
    assert curve_points(bad, samples_per_segment=1).tolist() == [[0, 0], [1, 1]]
    assert [len(p) for p in curve_pieces(bad)] == [0, 0, 2]
    with pytest.raises(ValueError, match="figure data"):
        curve_pieces({"lines": []})


def test_every_axes_is_read_and_empty_figures_give_no_points():
    fig = figure([line([0, 1], [0, 0])])
    fig["axes"].append(figure([line([5, 6], [5, 5])])["axes"][0])
    assert curve_points(fig).max() == 6.0
    assert curve_points({"axes": []}).shape == (0, 2)
    assert curve_points(figure()).shape == (0, 2)


@pytest.mark.parametrize("bad", [None, [], {"lines": []}, {"axes": "no"}])
def test_curve_points_refuses_non_figures(bad):
    with pytest.raises(ValueError, match="figure data"):
        curve_points(bad)


def test_curve_points_refuses_bad_samples():
    with pytest.raises(ValueError, match="samples_per_segment"):
        curve_points(figure(), samples_per_segment=0)


def test_drawing_style_does_not_change_the_distance():
    """One line, one line per piece, a dense scatter, a LineCollection: same curve."""
    ring = circle(2001)
    reference = circle(8000)
    one = figure([line(ring[:, 0], ring[:, 1])])
    pieces = figure([line(p[:, 0], p[:, 1]) for p in np.array_split(ring, 7)])
    scatter = figure(collections=[{"kind": "PathCollection", "offsets": ring, "segments": [],
                                   "array": None}])
    collection = figure(collections=[{"kind": "LineCollection", "offsets": np.empty((0, 2)),
                                      "segments": np.array_split(ring, 5), "array": None}])
    worst = [relative_curve_distance(curve_points(fig), reference).worst
             for fig in (one, pieces, scatter, collection)]
    assert max(worst) < 1e-3
    assert max(worst) - min(worst) < 5e-4


def test_coarse_polyline_covers_its_segments():
    """A square drawn with its 5 corners is close to a dense square."""
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], dtype=float)
    t = np.linspace(0, 1, 101)[:-1, None]
    dense = np.vstack([a + t * (b - a) for a, b in zip(corners[:-1], corners[1:])])
    d = relative_curve_distance(curve_points(figure([line(corners[:, 0], corners[:, 1])])), dense)
    assert d.forward < 0.05 / 2 + 1e-12  # 20 samples per unit segment: gaps of 0.05
    assert d.backward < 0.005 + 1e-12


# ---------------------------------------------------------------------------
# distances
# ---------------------------------------------------------------------------

def test_hausdorff_on_known_sets():
    a = np.array([[0.0, 0.0], [1.0, 0.0]])
    b = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0]])
    assert hausdorff(a, b) == (0.0, 3.0)
    assert hausdorff(b, a) == (3.0, 0.0)
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    assert hausdorff(square, [[1.0, 1.0]]) == (math.sqrt(2.0), math.sqrt(2.0))


def test_hausdorff_with_empty_sets():
    assert hausdorff(np.empty((0, 2)), [[1.0, 2.0]]) == (0.0, math.inf)
    assert hausdorff([[1.0, 2.0]], []) == (math.inf, 0.0)


def test_relative_distance_names_missing_and_extra_parts():
    reference = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]])  # diagonal 5
    student = np.array([[0.0, 0.0], [3.0, 0.0], [10.0, 0.0]])   # misses (3, 4), adds (10, 0)
    d = relative_curve_distance(student, reference)
    assert isinstance(d, CurveDistance)
    assert d.scale == 5.0
    assert d.forward == 4.0 and d.forward_at == (3.0, 4.0)
    assert d.backward == 7.0 and d.backward_at == (10.0, 0.0)
    assert d.worst == pytest.approx(7.0 / 5.0)
    with pytest.raises(AttributeError):
        d.forward = 0.0  # frozen
    assert d.gaps("triangle", 0.5) == (
        "parts of the triangle are missing from your drawing (the farthest reference point is "
        "4 units from any of your curves, near (3.0, 4.0)); your drawing has extra parts (e.g. "
        "near (10.0, 0.0), 7 units from the reference)")
    assert d.gaps("triangle", 1.0) == "your drawing has extra parts (e.g. near (10.0, 0.0), " \
                                      "7 units from the reference)"
    assert d.gaps("triangle", 2.0) == ""


def test_relative_distance_without_student_points():
    d = relative_curve_distance(np.empty((0, 2)), circle(50))
    assert d.forward == math.inf and d.worst == math.inf and d.forward_at is None
    assert d.gaps("circle", 0.02) == "the circle is missing from your drawing: it has no curves"


def test_relative_distance_needs_a_reference():
    with pytest.raises(ValueError, match="reference_pts"):
        relative_curve_distance(circle(10), np.empty((0, 2)))
    with pytest.raises(ValueError, match="same point"):
        relative_curve_distance(circle(10), np.ones((3, 2)))


def test_engine_holds_no_course_content():
    """The engine never imports the model solutions: the car belongs to its assignment."""
    import ast
    from pathlib import Path

    package = Path(__file__).resolve().parents[2] / "autograder"
    for path in package.rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            assert not any(n == "reference" or n.startswith("reference.") for n in names), (
                f"{path.relative_to(package.parent)} imports {names}")


# ---------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------

def draw_circle(ax):
    ring = circle(13)
    ax.plot(ring[:, 0], ring[:, 1])


def _student_png():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(3, 2))
    FigureCanvasAgg(fig)
    ring = circle(100)
    fig.add_subplot().plot(ring[:, 0], ring[:, 1])
    out = io.BytesIO()
    fig.savefig(out, format="png", dpi=40)
    return out.getvalue()


@pytest.mark.parametrize("student_png", [_student_png(), None, b"not a png",
                                         PNG_SIGNATURE + b"truncated"])
def test_side_by_side_is_a_png(student_png):
    import matplotlib.image as mpimg

    png = render_side_by_side(student_png, draw_circle, title="test")
    assert png.startswith(PNG_SIGNATURE)
    height, width = mpimg.imread(io.BytesIO(png), format="png").shape[:2]
    assert (width, height) == (800, 320)


def test_side_by_side_accepts_png_as_uint8_array():
    png = np.frombuffer(_student_png(), dtype=np.uint8)
    assert render_side_by_side(png, draw_circle).startswith(PNG_SIGNATURE)


def test_side_by_side_draws_the_reference_with_the_given_function():
    drawn = []

    def draw(ax):
        drawn.append(ax)
        ax.plot([0, 1], [0, 1])

    render_side_by_side(None, draw, right_title="the car")
    assert len(drawn) == 1 and drawn[0].get_title() == "the car"


def test_png_bombs_are_not_decoded():
    """A small file may claim a huge picture: the header is read, the pixels never."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(
            ">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", 13_000, 13_000, 8, 2, 0, 0, 0)
    bomb = PNG_SIGNATURE + chunk(b"IHDR", header) + chunk(b"IEND", b"")
    assert decode_png(bomb) is None
    assert decode_png(_student_png()) is not None
    assert decode_png(_student_png(), max_pixels=10) is None
