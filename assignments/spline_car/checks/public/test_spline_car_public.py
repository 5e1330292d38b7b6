"""Public checks for the spline car: small point sets and the car of ``data/car.npz``.

Run them with ``autograder check spline_car.ipynb``. The expected coefficients
below are exact fractions, small enough to verify by hand: solve the 2 x 2 or
3 x 3 system for M_1, ..., M_(n-1), then use the formulas for a, b, c, d.
The graded checks use more and harder point sets (uneven spacing, hundreds of
points, unseen data), a convergence test, and unseen drawings.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import spline_feedback as judge  # checks/public/spline_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Feedback, Student, over_datasets

CAR_NPZ = Path(__file__).resolve().parents[2] / "data" / "car.npz"

#: Exact answers: any correct method agrees to rounding (~1e-15); 1e-9 leaves ample room.
RTOL = 1e-9


def _rows(*rows: list[str]) -> np.ndarray:
    return np.array([[float(Fraction(v)) for v in row] for row in rows])


#: name -> (x, y, expected rows [a, b, c, d]); M are the second derivatives at the knots
SMALL = {
    # two points: the natural spline is the straight line (M_0 = M_1 = 0)
    "line-2pts": ([0.5, 2.0], [1.0, 4.0], _rows(["1", "2", "0", "0"])),
    # the notebook's worked example: M = [0, -4, 4, 0]
    "worked-example": ([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 0.0, 1.0],
                       _rows(["0", "5/3", "0", "-2/3"], ["1", "-1/3", "-2", "4/3"],
                             ["0", "-1/3", "2", "-2/3"])),
    # gaps 1, 2, 1: M = [0, -3, 3, 0]
    "uneven-4": ([0.0, 1.0, 3.0, 4.0], [1.0, 2.0, 0.0, 1.0],
                 _rows(["1", "3/2", "0", "-1/2"], ["2", "0", "-3/2", "1/2"],
                       ["0", "0", "3/2", "-1/2"])),
    # y = x^2: the natural spline is not the parabola (it must have S'' = 0 at the ends);
    # M = [0, 18/7, 12/7, 18/7, 0]
    "parabola-5": ([0.0, 1.0, 2.0, 3.0, 4.0], [0.0, 1.0, 4.0, 9.0, 16.0],
                   _rows(["0", "4/7", "0", "3/7"], ["1", "13/7", "9/7", "-1/7"],
                         ["4", "4", "6/7", "1/7"], ["9", "43/7", "9/7", "-3/7"])),
}


def _load_car() -> list[np.ndarray]:
    with np.load(CAR_NPZ, allow_pickle=False) as data:
        return [data[key] for key in sorted(data.files)]


@over_datasets(SMALL, "case", points=1)
def test_spline_coefficients_small(student: Student, credit: Credit, case: str) -> None:
    x, y, expected = (np.array(v, dtype=float) for v in SMALL[case])
    got = student.spline_coefficients(x, y)
    judge.grade_coefficients(got, x, y, expected, credit, rtol=RTOL)


@pytest.mark.points(1)
def test_natural_ends_small(student: Student, credit: Credit) -> None:
    x, y, _ = (np.array(v, dtype=float) for v in SMALL["uneven-4"])
    reading = judge.read_coefficients(student.spline_coefficients(x, y), x, y)
    judge.check_natural_ends(reading, x, y, RTOL)
    judge.finish(reading, credit)


@pytest.mark.points(1)
def test_spline_eval_small(student: Student, credit: Credit) -> None:
    x, y, rows = (np.array(v, dtype=float) for v in SMALL["worked-example"])
    t = np.array([0.0, 1.0, 2.0, 3.0, 0.5, 1.5, 2.25])
    # S_0(0.5) = 5/3 * 0.5 - 2/3 * 0.125, S_1(1.5) = 1/2 by symmetry, S_2(2.25) from row 2
    expected = np.array([0.0, 1.0, 0.0, 1.0, 0.75, 0.5, -1 / 12 + 1 / 8 - 1 / 96])
    got = student.spline_eval(x, rows, t)
    judge.grade_eval(got, x, t, expected, rtol=RTOL, credit=credit,
                        retry_reversed=lambda: student.spline_eval(x, rows[:, ::-1].copy(), t))


@pytest.mark.points(3)
def test_draw_car(student: Student, credit: Credit, feedback: Feedback) -> None:
    strokes = _load_car()
    fig = student.draw_car(strokes)
    judge.grade_drawing(fig, strokes, credit, feedback)
