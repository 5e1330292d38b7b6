"""Tests of reference.car and its .npz file: the car strokes."""

from __future__ import annotations

import re

import numpy as np
import pytest

import reference._data as data
from reference import CAR_STROKE_NAMES, car, load_strokes, parametric_spline, save_car

CLOSED = {"rear_window", "front_window", "rear_wheel", "front_wheel", "rear_hubcap", "front_hubcap"}
# How far the drawn spline may leave the bounding box of its points, as a
# fraction of the box's size.  The brief allows 10%; the data manage 3%.
OVERSHOOT = 0.03
SAMPLES = 400


def strokes_by_name():
    return dict(zip(CAR_STROKE_NAMES, car()))


def test_strokes_shapes_and_names():
    strokes = car()
    assert isinstance(strokes, list)
    assert 6 <= len(strokes) <= 10
    assert len(CAR_STROKE_NAMES) == len(strokes) == len(set(CAR_STROKE_NAMES))
    for name, stroke in zip(CAR_STROKE_NAMES, strokes):
        assert isinstance(stroke, np.ndarray) and stroke.dtype == np.float64, name
        assert stroke.ndim == 2 and stroke.shape[1] == 2, name
        assert 8 <= stroke.shape[0] <= 40, (name, stroke.shape)
        assert np.all(np.isfinite(stroke)), name


def test_coordinates_fit_the_page():
    points = np.vstack(car())
    assert points[:, 0].min() >= 0.0 and points[:, 0].max() <= 10.0
    assert points[:, 1].min() >= 0.0 and points[:, 1].max() <= 4.0
    assert np.ptp(points[:, 0]) > 9.0 and np.ptp(points[:, 1]) > 3.0


def test_closed_strokes_are_closed():
    for name, stroke in strokes_by_name().items():
        closed = np.array_equal(stroke[0], stroke[-1])
        assert closed == (name in CLOSED), name


@pytest.mark.parametrize("name", ["rear_wheel", "front_wheel", "rear_hubcap", "front_hubcap"])
def test_wheels_are_circles(name):
    stroke = strokes_by_name()[name]
    centre = stroke[:-1].mean(axis=0)
    radius = np.linalg.norm(stroke - centre, axis=1)
    assert np.ptp(radius) < 1e-12
    curve = parametric_spline(stroke).sample(SAMPLES)
    drawn = np.linalg.norm(curve - centre, axis=1)
    assert np.abs(drawn / radius[0] - 1).max() < 0.01  # natural ends: slightly off near the seam


def test_wheels_sit_under_the_arches():
    s = strokes_by_name()
    for wheel, hub in (("rear_wheel", "rear_hubcap"), ("front_wheel", "front_hubcap")):
        np.testing.assert_allclose(s[wheel][:-1].mean(0), s[hub][:-1].mean(0), atol=1e-12)
    rear, front = s["rear_wheel"][:-1].mean(0), s["front_wheel"][:-1].mean(0)
    assert rear[0] < front[0] and abs(rear[1] - front[1]) < 1e-12
    assert s["body"][:, 1].max() > s["rear_wheel"][:, 1].max() + 1.0


def test_no_repeated_consecutive_points():
    for name, stroke in strokes_by_name().items():
        steps = np.linalg.norm(np.diff(stroke, axis=0), axis=1)
        assert steps.min() > 0.01, name


@pytest.mark.parametrize("name", CAR_STROKE_NAMES)
def test_spline_of_each_stroke_does_not_overshoot(name):
    stroke = strokes_by_name()[name]
    curve = parametric_spline(stroke).sample(SAMPLES)
    lo, hi = stroke.min(axis=0), stroke.max(axis=0)
    size = hi - lo
    assert np.all(curve.min(axis=0) >= lo - OVERSHOOT * size), name
    assert np.all(curve.max(axis=0) <= hi + OVERSHOOT * size), name


def segments_cross(poly: np.ndarray, closed: bool) -> bool:
    """Whether two non-neighbouring segments of a polyline properly intersect."""
    a, b = poly[:-1], poly[1:]
    m = a.shape[0]

    def orient(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    A, B = a[:, None], b[:, None]
    C, D = a[None, :], b[None, :]
    cross = (orient(A, B, C) * orient(A, B, D) < 0) & (orient(C, D, A) * orient(C, D, B) < 0)
    i, j = np.triu_indices(m, k=2)
    keep = ~((i == 0) & (j == m - 1)) if closed else np.ones(i.size, bool)
    return bool(np.any(cross[i[keep], j[keep]]))


@pytest.mark.parametrize("name", CAR_STROKE_NAMES)
def test_spline_of_each_stroke_has_no_loops(name):
    stroke = strokes_by_name()[name]
    curve = parametric_spline(stroke).sample(SAMPLES)
    assert not segments_cross(curve, closed=name in CLOSED), name


def test_loop_detector_finds_a_loop():
    figure_eight = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], dtype=float)
    assert segments_cross(figure_eight, closed=False)
    assert not segments_cross(np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]], float), closed=True)


def test_each_call_returns_fresh_arrays():
    first = car()
    first[0][:] = -1.0
    first.append(np.zeros((3, 2)))
    second = car()
    assert len(second) == len(CAR_STROKE_NAMES)
    assert np.all(second[0] >= 0.0)


def test_save_and_load_round_trip(tmp_path):
    written = save_car(tmp_path / "car.npz")
    assert written == tmp_path / "car.npz" and written.exists()
    with np.load(written, allow_pickle=False) as archive:
        assert sorted(archive.files) == [f"stroke_{k:02d}" for k in range(len(CAR_STROKE_NAMES))]
    loaded = load_strokes(str(written))
    assert len(loaded) == len(CAR_STROKE_NAMES)
    for got, want in zip(loaded, car()):
        np.testing.assert_array_equal(got, want)
        assert got.dtype == np.float64


def test_save_overwrites(tmp_path):
    path = tmp_path / "car.npz"
    path.write_bytes(b"old")
    save_car(path)
    assert len(load_strokes(path)) == len(CAR_STROKE_NAMES)


@pytest.mark.parametrize(
    "arrays, message",
    [
        ({"stroke_00": np.zeros((3, 2)), "names": np.zeros(2)}, "found 'names'"),
        ({"stroke_00": np.zeros((3, 2)), "stroke_1": np.zeros((3, 2))}, "found 'stroke_1'"),
        ({"stroke_00": np.zeros((3, 2)), "stroke_02": np.zeros((3, 2))}, "stroke 01 is missing"),
        ({"stroke_00": np.zeros((3, 3))}, "`stroke_00` must have shape (n, 2); got (3, 3)."),
        ({"stroke_00": np.array([[0.0, np.nan]])}, "`stroke_00` must contain only finite values"),
        ({}, "must hold at least one stroke"),
    ],
)
def test_load_rejects_bad_files(tmp_path, arrays, message):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(ValueError, match=re.escape(message)):
        load_strokes(path)


def test_load_and_save_reject_bad_paths(tmp_path):
    with pytest.raises(ValueError, match=re.escape("`path` must name a .npz file")):
        save_car(tmp_path / "car.npy")
    with pytest.raises(ValueError, match=re.escape("`path` must be a path")):
        load_strokes(42)
    not_zip = tmp_path / "junk.npz"
    not_zip.write_text("not a zip archive")
    with pytest.raises(ValueError, match=re.escape("`path` must be a NumPy .npz archive")):
        load_strokes(not_zip)
    single = tmp_path / "single.npz"
    with open(single, "wb") as handle:
        np.save(handle, np.zeros((3, 2)))
    with pytest.raises(ValueError, match=re.escape("holds a single array")):
        load_strokes(single)
    with pytest.raises(FileNotFoundError):
        load_strokes(tmp_path / "missing.npz")
