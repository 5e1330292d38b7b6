"""Tests of autograder.worker.figures: figure data from real (Agg) figures, and its trip
through the protocol."""

from __future__ import annotations

import datetime
import json
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from autograder.worker import figures  # selects Agg before pyplot is imported

import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.tri as mtri  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

from autograder.boundary.codec import decode, encode  # noqa: E402
from autograder.boundary.frames import recv_message, send_message  # noqa: E402
from autograder.boundary.values import Unsupported  # noqa: E402
from autograder.worker.figures import (  # noqa: E402
    close_all,
    figure_to_data,
    figures_data,
    open_figure_numbers,
    open_figures_data,
)

ROOT = Path(__file__).resolve().parents[2]
RNG_SEED = 20240601


@pytest.fixture(autouse=True)
def _close_figures():
    plt.close("all")
    yield
    plt.close("all")


@pytest.fixture
def points():
    """30 random points in the unit square and a smooth function of them (seeded)."""
    rng = np.random.default_rng(RNG_SEED)
    x, y = rng.random(30), rng.random(30)
    return x, y, x**2 + y


def test_line_data():
    x = np.linspace(0, 1, 11)
    plt.plot(x, x**2, "r--o", label="square")
    plt.plot([3, 1, 2])  # y only: x is 0, 1, 2
    data = figure_to_data(plt.gcf())
    assert data["$t"] == "figure" and len(data["axes"]) == 1
    first, second = data["axes"][0]["lines"]
    assert type(first["x"]) is np.ndarray and first["x"].dtype == np.float64
    np.testing.assert_array_equal(first["x"], x)
    np.testing.assert_array_equal(first["y"], x**2)
    assert (first["label"], first["color"], first["linestyle"], first["marker"]) == ("square", "#ff0000", "--", "o")
    np.testing.assert_array_equal(second["x"], [0, 1, 2])
    np.testing.assert_array_equal(second["y"], [3, 1, 2])
    assert data["truncated"] is False and data["notes"] == []


def test_masked_line_values_become_nan():
    plt.plot(np.ma.masked_array([1.0, 2.0, 3.0], mask=[False, True, False]))
    y = figure_to_data(plt.gcf())["axes"][0]["lines"][0]["y"]
    np.testing.assert_array_equal(y, [1.0, np.nan, 3.0])


def test_scatter_offsets(points):
    x, y, z = points
    fig, ax = plt.subplots()
    ax.scatter(x, y, c=z)
    (coll,) = figure_to_data(fig)["axes"][0]["collections"]
    assert coll["kind"] == "PathCollection"
    np.testing.assert_array_equal(coll["offsets"], np.column_stack([x, y]))
    np.testing.assert_array_equal(coll["array"], z)
    assert coll["segments"] == []  # marker shapes are in points, not data


def test_tricontourf_paths(points):
    x, y, z = points
    fig, ax = plt.subplots()
    cs = ax.tricontourf(x, y, z, levels=5)
    (coll,) = figure_to_data(fig)["axes"][0]["collections"]
    assert coll["kind"] == "TriContourSet"
    assert len(coll["segments"]) >= len(cs.levels) - 1
    vertices = np.concatenate(coll["segments"])
    assert vertices.shape[1] == 2 and len(vertices) > 20
    # filled contours of a function on the points stay inside their bounding box
    assert np.all(vertices.min(axis=0) >= [x.min() - 1e-9, y.min() - 1e-9])
    assert np.all(vertices.max(axis=0) <= [x.max() + 1e-9, y.max() + 1e-9])
    np.testing.assert_array_equal(coll["array"], cs.get_array())
    assert coll["offsets"].shape == (0, 2)


def test_tripcolor_and_triplot(points):
    x, y, z = points
    fig, ax = plt.subplots()
    triangulation = mtri.Triangulation(x, y)
    ax.tripcolor(triangulation, z)
    ax.triplot(triangulation, "k-")
    axes = figure_to_data(fig)["axes"][0]
    (coll,) = axes["collections"]
    assert len(coll["segments"]) == len(triangulation.triangles)
    assert all(s.shape == (3, 2) for s in coll["segments"])
    known = {(a, b) for a, b in zip(x, y)}
    for segment in coll["segments"]:
        assert {tuple(p) for p in segment} <= known
    edges = axes["lines"][0]
    finite = ~np.isnan(edges["x"])
    assert {(a, b) for a, b in zip(edges["x"][finite], edges["y"][finite])} == known


def test_fill_patch_and_bar():
    fig, ax = plt.subplots()
    ax.fill([0, 1, 1], [0, 0, 2])
    ax.bar([5], [3], width=1)
    fill, bar = figure_to_data(fig)["axes"][0]["patches"]
    assert fill["kind"] == "Polygon"
    assert {tuple(p) for p in fill["vertices"]} == {(0, 0), (1, 0), (1, 2)}
    assert bar["kind"] == "Rectangle"
    np.testing.assert_allclose(bar["vertices"].min(axis=0), [4.5, 0])
    np.testing.assert_allclose(bar["vertices"].max(axis=0), [5.5, 3])


def test_imshow_and_fill_between():
    fig, ax = plt.subplots()
    ax.imshow(np.zeros((3, 4)), extent=(0, 4, 0, 3))
    ax.fill_between([0, 1, 2], [0, 1, 0], [1, 2, 1])
    axes = figure_to_data(fig)["axes"][0]
    assert axes["images"] == [{"shape": [3, 4], "extent": [0.0, 4.0, 0.0, 3.0]}]
    (band,) = axes["collections"]
    assert {tuple(p) for p in band["segments"][0]} >= {(0, 0), (2, 0), (1, 2)}


def test_several_subplots_labels_and_png():
    fig, axs = plt.subplots(2, 2, figsize=(4, 3))
    axs[0, 0].plot([0, 1], [0, 1], label="diagonal")
    axs[0, 0].legend()
    axs[0, 0].set(title="hull", xlabel="x", ylabel="y", xlim=(-1, 2), aspect="equal")
    axs[1, 1].text(0.5, 0.5, "note")
    axs[1, 1].set_aspect(2)
    fig.suptitle("car")
    data = figure_to_data(fig, dpi=50)
    assert len(data["axes"]) == 4
    first = data["axes"][0]
    assert (first["title"], first["xlabel"], first["ylabel"]) == ("hull", "x", "y")
    assert first["xlim"] == [-1.0, 2.0] and first["aspect"] == "equal" and first["legend"] == ["diagonal"]
    assert data["axes"][1]["aspect"] == "auto" and data["axes"][3]["aspect"] == 2.0
    assert data["axes"][3]["texts"] == ["note"]
    assert data["suptitle"] == "car"
    assert data["png"].startswith(b"\x89PNG")
    width, height = int.from_bytes(data["png"][16:20], "big"), int.from_bytes(data["png"][20:24], "big")
    assert (width, height) == (200, 150)


def test_figure_made_without_pyplot():
    fig = Figure()
    fig.add_subplot().plot([1, 2], [3, 4])
    data = figure_to_data(fig)
    assert data["png"].startswith(b"\x89PNG")
    np.testing.assert_array_equal(data["axes"][0]["lines"][0]["y"], [3, 4])


def test_date_and_string_lines_are_skipped_with_a_note():
    fig, ax = plt.subplots()
    ax.plot([datetime.date(2024, 1, d) for d in (1, 2, 3)], [1, 2, 3])
    fig2, ax2 = plt.subplots()
    ax2.plot(["a", "b"], [1, 2])
    ax2.plot([0, 1], [5, 6])
    data = figure_to_data(fig)
    assert data["axes"][0]["lines"] == [] and "line 0 skipped" in data["notes"][0]
    data2 = figure_to_data(fig2)
    assert len(data2["axes"][0]["lines"]) == 1 and len(data2["notes"]) == 1


def test_a_broken_artist_does_not_break_the_figure():
    class BrokenLine(Line2D):
        def get_xdata(self, orig=True):
            raise RuntimeError("hostile artist")

    fig, ax = plt.subplots()
    ax.add_line(BrokenLine([0, 1], [0, 1]))
    ax.plot([1, 2], [3, 4])
    data = figure_to_data(fig)
    assert len(data["axes"][0]["lines"]) == 1
    assert "RuntimeError: hostile artist" in data["notes"][0]
    assert data["png"].startswith(b"\x89PNG")


def test_points_are_capped():
    fig, ax = plt.subplots()
    ax.plot(np.arange(1000.0), np.arange(1000.0))
    ax.scatter(np.arange(500.0), np.arange(500.0))
    x, y = np.meshgrid(np.arange(30.0), np.arange(30.0))
    ax.tricontourf(x.ravel(), y.ravel(), (x + y).ravel())
    data = figure_to_data(fig, max_points=1200)
    axes = data["axes"][0]
    assert data["truncated"] is True
    kept = len(axes["lines"][0]["x"]) + sum(
        len(c["offsets"]) + sum(len(s) for s in c["segments"]) + (0 if c["array"] is None else c["array"].size)
        for c in axes["collections"]
    )
    assert kept <= 1200
    assert len(axes["lines"][0]["x"]) == 1000 and len(axes["collections"][0]["offsets"]) == 200


def test_huge_figure_is_rendered_at_a_lower_dpi():
    fig = plt.figure(figsize=(200, 200))
    data = figure_to_data(fig, dpi=72)
    width = int.from_bytes(data["png"][16:20], "big")
    assert width <= 2000


def test_not_a_figure():
    with pytest.raises(TypeError, match="matplotlib Figure"):
        figure_to_data(object())


def test_open_figures_and_close_all():
    plt.figure()
    plt.plot([1, 2])
    before = open_figure_numbers()
    second = plt.figure()
    plt.scatter([1], [2])
    first = plt.figure(1)
    data = open_figures_data()
    assert [len(d["axes"][0]["lines"]) for d in data] == [1, 0]
    assert plt.gcf() is first  # the current figure is left alone
    assert before == [1] and open_figure_numbers() == [1, second.number]
    (new,) = figures_data(exclude=before)
    assert len(new["axes"][0]["collections"]) == 1
    close_all()
    assert plt.get_fignums() == [] and open_figures_data() == []


def test_figure_data_sent_as_a_dict_equals_the_figure_sent_as_a_figure():
    plt.plot([1.0, 2.0], [3.0, 4.0])
    (as_dict,) = open_figures_data()
    tree, buffers = encode([as_dict, plt.gcf()], figure_encoder=figure_to_data)
    from_dict, from_figure = decode(tree, buffers)
    assert from_dict.keys() == from_figure.keys() and from_dict["$t"] == "figure"
    np.testing.assert_array_equal(from_dict["axes"][0]["lines"][0]["y"], [3.0, 4.0])
    np.testing.assert_array_equal(from_figure["axes"][0]["lines"][0]["y"], [3.0, 4.0])
    assert type(from_dict["png"]) is bytes and type(from_figure["png"]) is bytes


# --------------------------------------------------------------------------
# across the boundary


def test_figure_survives_encode_frames_decode(points):
    x, y, z = points
    fig, axs = plt.subplots(1, 2)
    axs[0].plot(x, y, "o", label="points")
    axs[1].tricontourf(x, y, z)
    a, b = socket.socketpair()
    try:
        sender = threading.Thread(target=send_message, args=(a, {"figure": fig, "axes": axs[0]}),
                                  kwargs={"figure_encoder": figure_to_data})
        sender.start()
        got = recv_message(b, timeout=20)
        sender.join()
    finally:
        a.close()
        b.close()
    data = got["figure"]
    assert type(data) is dict and data["$t"] == "figure"
    assert type(data["png"]) is bytes and data["png"].startswith(b"\x89PNG")
    line = data["axes"][0]["lines"][0]
    assert type(line["x"]) is np.ndarray and line["x"].base is None
    np.testing.assert_array_equal(line["x"], x)
    assert all(type(s) is np.ndarray for s in data["axes"][1]["collections"][0]["segments"])
    assert got["axes"]["png"].startswith(b"\x89PNG")  # an Axes crosses as its figure


def test_other_matplotlib_objects_are_unsupported():
    (line,) = plt.plot([1, 2])
    tree, buffers = encode([line], figure_encoder=figure_to_data)
    (got,) = decode(tree, buffers)
    assert type(got) is Unsupported and got.type == "matplotlib.lines.Line2D"


def test_decoding_figure_data_needs_no_matplotlib(tmp_path):
    plt.plot([1, 2, 3], [3, 1, 2])
    tree, buffers = encode(plt.gcf(), figure_encoder=figure_to_data)
    (tmp_path / "tree.json").write_text(json.dumps(tree))
    for i, buffer in enumerate(buffers):
        (tmp_path / f"{i}.bin").write_bytes(bytes(buffer))
    script = f"""
import json, sys
from pathlib import Path
sys.modules["matplotlib"] = None  # any matplotlib import now fails
from autograder.boundary.codec import decode
d = Path({str(tmp_path)!r})
tree = json.loads((d / "tree.json").read_text())
data = decode(tree, [(d / f"{{i}}.bin").read_bytes() for i in range({len(buffers)})])
assert data["axes"][0]["lines"][0]["y"].tolist() == [3.0, 1.0, 2.0]
assert data["png"][:4] == b"\\x89PNG"
print("ok")
"""
    result = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert result.stdout.strip() == "ok", result.stderr


def test_figures_module_imports_nothing_else_from_autograder():
    source = Path(figures.__file__).read_text()
    imports = [line for line in source.splitlines() if line.startswith(("import autograder", "from autograder"))]
    assert all(line.startswith("from autograder.boundary.") for line in imports)
