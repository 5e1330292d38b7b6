"""Public checks for the convex-hull assignment: small pin sets and ``data/pins.csv``.

Run them with ``autograder check hull.ipynb``. The graded checks use more and
harder point sets than these (larger, nearly collinear, and unseen layouts).
The answers here are small enough to verify by hand on squared paper.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hull_feedback as feedback  # checks/public/hull_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Student, over_datasets

PINS_CSV = Path(__file__).resolve().parents[2] / "data" / "pins.csv"

#: (p, q, r, sign of the turn p -> q -> r); all exact, no tolerance involved
TURNS = {
    "turns": [
        ((0, 0), (1, 0), (0, 1), 1),
        ((0, 0), (0, 1), (1, 0), -1),
        ((1, 1), (4, 2), (2, 5), 1),
        ((-2.5, 3.0), (0.0, 0.0), (5.0, -1.0), 1),
        ((3, 3), (5, 1), (1, 0), -1),
    ],
    "collinear": [
        ((0, 0), (1, 1), (3, 3), 0),
        ((2, 0), (0, 0), (1, 0), 0),            # r between p and q
        ((1, 2), (1, 2), (5, -3), 0),           # two equal points
        ((0.1, 0.2), (0.3, 0.6), (0.7, 1.4), 0),  # y = 2x holds exactly for these doubles
        ((-1.0, 4.0), (-1.0, -2.5), (-1.0, 7.25), 0),
    ],
}

#: name -> (points, expected hull, every pin on the boundary in counter-clockwise order)
HULLS = {
    "square-with-interior": (
        [[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]],
        [0, 1, 2, 3], [0, 1, 2, 3]),
    "worked-example": (
        [[2, 1], [4, 0], [0, 0], [2, 0], [1, 3]],
        [2, 1, 4], [2, 3, 1, 4]),
    "rectangle-edge-pins": (
        [[4, 2], [2, 0], [0, 2], [2, 1], [0, 0], [4, 0], [2, 2], [0, 1]],
        [4, 5, 0, 2], [4, 1, 5, 0, 6, 2, 7]),
    "single-pin": (
        [[3, 1]],
        [0], [0]),
    "collinear-pins": (
        [[2, 2], [0, 0], [3, 3], [1, 1]],
        [1, 2], [1, 3, 0, 2]),
}

#: cases that a stub can answer (one pin, pins on one line): earned only with a general hull
DEGENERATE = {"single-pin", "collinear-pins"}

#: the hull of data/pins.csv, and its boundary (pins 1 and 15 lie on edges)
PINS_HULL = [12, 5, 4, 7, 14, 26, 8, 28]
PINS_BOUNDARY = [12, 5, 4, 1, 7, 14, 26, 15, 8, 28]


@over_datasets(TURNS, "case", points=1)
def test_orientation_small(student: Student, case: str) -> None:
    general = feedback.GENERAL_TURNS if case == "collinear" else []
    # one batch: the general turns (for the collinear case), then the case's own triples
    answers = student.map("orientation", [(p, q, r) for p, q, r, _ in general + TURNS[case]])
    if general:
        feedback.require_general_turns(answers, "collinear cases")
    for (p, q, r, expected), got in zip(TURNS[case], answers):
        feedback.judge_turn(got, p, q, r, expected)


@over_datasets(HULLS, "case", points=1)
def test_convex_hull_small(student: Student, credit: Credit, case: str) -> None:
    raw, expected, boundary = HULLS[case]
    points = np.array(raw, dtype=float)
    if case in DEGENERATE:
        feedback.require_general_case(student.convex_hull, f"{case} case")
    got = student.convex_hull(points)
    feedback.grade_hull(got, points, expected, boundary, credit)


@pytest.mark.points(2)
def test_convex_hull_pins(student: Student, credit: Credit) -> None:
    points = np.loadtxt(PINS_CSV, delimiter=",", skiprows=1)
    got = student.convex_hull(points)
    feedback.grade_hull(got, points, PINS_HULL, PINS_BOUNDARY, credit)
