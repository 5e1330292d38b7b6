"""Public checks for the Delaunay assignment: small point sets, and the lake.

Run them with ``autograder check delaunay.ipynb``. The graded checks use more
and harder point sets than these: larger random sets, grids and circles where
many points are cocircular, thin slivers, clusters, and points that are a few
units in the last place away from a circle. Every answer here is small enough
to verify by hand, or (the lake) is stored beside this file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import delaunay_feedback as fb  # checks/public/delaunay_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Feedback, Student, over_datasets

HERE = Path(__file__).resolve().parent
LAKE_CSV = HERE.parents[1] / "data" / "lake.csv"
#: the Delaunay triangulation of data/lake.csv (unique: no four points are cocircular)
LAKE_TRIANGLES = HERE / "lake_triangles.csv"

#: (a, b, c, d, where d is: +1 strictly inside, 0 on, -1 outside the circle through a, b, c)
CIRCLES = {
    "inside-outside": [
        ((1, 0), (0, 1), (-1, 0), (0, 0), 1),
        ((1, 0), (0, 1), (-1, 0), (2, 2), -1),
        ((1, 0), (0, 1), (-1, 0), (0.5, -0.5), 1),
        ((0, 0), (4, 0), (0, 3), (2, 1.5), 1),        # the centre
        ((0, 0), (4, 0), (0, 3), (5, 5), -1),
        ((0, 0), (4, 0), (0, 3), (-0.5, 3.5), -1),
    ],
    "on-circle": [
        ((1, 0), (0, 1), (-1, 0), (0, -1), 0),
        ((0, 0), (4, 0), (0, 3), (4, 3), 0),          # fourth corner of the rectangle
        ((3, 4), (-4, 3), (-3, -4), (5, 0), 0),       # 3-4-5 triangles: radius 5
        ((3, 4), (-4, 3), (-3, -4), (0, 0), 1),
        ((3, 4), (-4, 3), (-3, -4), (6, 0), -1),
    ],
}

#: name -> (points, every valid Delaunay triangulation, each as counter-clockwise triples)
SMALL = {
    "triangle-3": (
        [[0, 0], [0.5, 2], [2, 1]],
        [[[0, 2, 1]]]),
    "worked-example": (
        [[0, 0], [4, 0], [2, 3], [2, 1], [5, 2]],
        [[[0, 1, 3], [0, 3, 2], [1, 4, 3], [2, 3, 4]]]),
    "square-4": (                                      # cocircular: either diagonal
        [[0, 0], [1, 0], [1, 1], [0, 1]],
        [[[0, 1, 2], [0, 2, 3]], [[0, 1, 3], [1, 2, 3]]]),
}


def lake_points() -> np.ndarray:
    return np.loadtxt(LAKE_CSV, delimiter=",", skiprows=1)


def lake_triangles() -> np.ndarray:
    return np.loadtxt(LAKE_TRIANGLES, delimiter=",", skiprows=1, dtype=np.int64)


def lake_depth(points: np.ndarray) -> np.ndarray:
    """A made-up depth in metres: deepest south-east of the middle, 0.5 m at the far shore."""
    x, y = points[:, 0], points[:, 1]
    return 0.5 + 11.5 * np.exp(-((x - 460.0) ** 2 + (y - 280.0) ** 2) / (2 * 160.0 ** 2))


@over_datasets(CIRCLES, "case", points=1)
def test_in_circle_small(student: Student, credit: Credit, case: str) -> None:
    quads = [(a, b, c, d) for a, b, c, d, _ in CIRCLES[case]]
    answers = student.map("in_circle", quads)  # one batch
    cases = [(quad, got, row[4]) for quad, got, row in zip(quads, answers, CIRCLES[case])]
    fb.judge_in_circle(cases, credit=credit)


@over_datasets(SMALL, "case", points=1)
def test_delaunay_small(student: Student, credit: Credit, case: str) -> None:
    raw, answers = SMALL[case]
    points = np.array(raw, dtype=float)
    got = student.delaunay(points)
    fb.grade_triangulation(got, len(points),
                           fb.known_answer_judge(points, answers), credit)


@pytest.mark.points(2)
def test_delaunay_lake(student: Student, credit: Credit) -> None:
    points = lake_points()
    got = student.delaunay(points)
    fb.grade_triangulation(got, len(points),
                           fb.known_answer_judge(points, [lake_triangles()]), credit)


@pytest.mark.points(2)
def test_plot_on_mesh_lake(student: Student, credit: Credit, feedback: Feedback) -> None:
    points = lake_points()
    fb.grade_figure(student, points, lake_triangles(), lake_depth(points), credit, feedback)
