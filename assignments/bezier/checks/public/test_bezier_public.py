"""Public checks for the Bezier assignment: the lecture's curves and a few small ones.

Run them with ``autograder check bezier.ipynb``. The graded checks use more
curves than these: a space curve, degree 40 (and 1100 for de_casteljau), a
polygon whose points all coincide, and random polygons this file never shows.

Expected points come from ``scipy.interpolate.BPoly`` (an independent
evaluation of the Bernstein form, allowed here, not in your notebook); the
worked examples of the notebook are also written out by hand below.
"""

from __future__ import annotations

import numpy as np

import bezier_feedback as fb  # checks/public/bezier_feedback.py: on sys.path while checks run
from autograder.checks import Credit, Feedback, Student, over_datasets

#: Allowed error, relative to the polygon's size (max |coordinate|, at least 1). Every
#: correct evaluation of these low-degree curves (Bernstein or de Casteljau, any order of
#: the operations) is within a few units of 1e-16; any slip is off by 1e-3 or more.
REL_TOL = 1e-12

#: name -> (control points, parameter values, hint shown when a value is wrong)
CURVES = {
    "quadratic-lecture": ([[0, 0], [1, 1], [1.2, 0.4]], (0.0, 0.25, 0.4, 0.5, 1.0), ""),
    "cubic-lecture": ([[0, 0], [4, 1], [9, 1], [3, 4]], (0.0, 0.3, 0.7, 1.0), ""),
    "line": ([[-1, 2], [3, 0.5]], (0.0, 0.5, 0.8, 1.0),
             "With two control points the curve is the segment (1 - t) P_0 + t P_1."),
    "degree-0": ([[1.5, -2.0]], (0.0, 0.6, 1.0),
                 ("One control point (n = 0) is a curve that stays at that point: its only "
                  "weight is B_{0,0}(t) = 1, for every t.")),
}

#: The notebook's worked examples, by hand: name -> (t, C(t)).
WORKED = {
    "quadratic-lecture": (0.4, (0.672, 0.544)),
    "cubic-lecture": (0.7, (5.754, 2.002)),
}

#: Polygons for the exact-endpoint checks. In "tenths", P + 1.0 * (Q - P) differs from Q
#: in the last bit (2.9 + (0.7 - 2.9) != 0.7), so only (1 - t) * P + t * Q passes at t = 1.
ENDPOINTS = {"lecture-and-tenths": [
    [[0, 0], [1, 1], [1.2, 0.4]],
    [[0, 0], [4, 1], [9, 1], [3, 4]],
    [[0.3, 0.1], [0.1, 0.7], [2.9, 0.3], [0.7, 0.2]],
]}

#: name -> (control points, t, left polygon, right polygon), all by hand
SPLITS = {
    "quadratic-lecture": ([[0, 0], [1, 1], [1.2, 0.4]], 0.4,
                          [[0, 0], [0.4, 0.4], [0.672, 0.544]],
                          [[0.672, 0.544], [1.08, 0.76], [1.2, 0.4]]),
    "cubic-lecture": ([[0, 0], [4, 1], [9, 1], [3, 4]], 0.7,
                      [[0, 0], [2.8, 0.7], [6.09, 0.91], [5.754, 2.002]],
                      [[5.754, 2.002], [5.61, 2.47], [4.8, 3.1], [3, 4]]),
}


def _expected(name: str, ctrl: np.ndarray, t: float) -> np.ndarray:
    """The oracle's point, checked against the hand-worked example where there is one."""
    point = fb.curve_points(ctrl, t)
    if name in WORKED and WORKED[name][0] == t and not np.allclose(point, WORKED[name][1],
                                                                   rtol=0, atol=1e-14):
        raise RuntimeError(f"BPoly disagrees with the worked example {name}: fix the oracle.")
    return point


def _grade_points(student: Student, credit: Credit, fn: str, name: str) -> None:
    raw, ts, hint = CURVES[name]
    ctrl = np.array(raw, dtype=float)
    atol = REL_TOL * fb.size(ctrl)
    broken = fb.CONVENTIONS.record()
    for t in ts:
        got = fb.ask(student, fn, ctrl, t)
        fb.judge_point(got, _expected(name, ctrl, t), fn=fn, ctrl=ctrl, t=t, atol=atol,
                       broken=broken, hint=hint)
    broken.finish(credit)


@over_datasets(CURVES, points=1)
def test_eval_bezier(student: Student, credit: Credit, name: str) -> None:
    _grade_points(student, credit, "eval_bezier", name)


@over_datasets(CURVES, points=1)
def test_de_casteljau(student: Student, credit: Credit, name: str) -> None:
    _grade_points(student, credit, "de_casteljau", name)


def _grade_endpoints(student: Student, credit: Credit, fn: str, name: str) -> None:
    polygons = [np.array(raw, dtype=float) for raw in ENDPOINTS[name]]
    fb.grade_endpoints(student, credit, fn, polygons, rtol=REL_TOL)


@over_datasets(ENDPOINTS, points=1)
def test_eval_bezier_endpoints(student: Student, credit: Credit, name: str) -> None:
    _grade_endpoints(student, credit, "eval_bezier", name)


@over_datasets(ENDPOINTS, points=1)
def test_de_casteljau_endpoints(student: Student, credit: Credit, name: str) -> None:
    _grade_endpoints(student, credit, "de_casteljau", name)


@over_datasets(SPLITS, points=1)
def test_split_bezier(student: Student, credit: Credit, feedback: Feedback, name: str) -> None:
    raw, t, left, right = SPLITS[name]
    ctrl = np.array(raw, dtype=float)
    expected = (np.array(left, dtype=float), np.array(right, dtype=float))
    samples = np.linspace(0.0, 1.0, 5)
    for poly, where in ((expected[0], t * samples), (expected[1], t + (1 - t) * samples)):
        if not np.allclose(fb.curve_points(poly, samples), fb.curve_points(ctrl, where),
                           rtol=0, atol=1e-13):
            raise RuntimeError(f"The hand-worked split {name} is wrong: fix the oracle.")
    broken = fb.CONVENTIONS.record()
    fb.grade_split(student, ctrl, t, expected, atol=REL_TOL * fb.size(ctrl), broken=broken,
                   picture=feedback.image)
    broken.finish(credit)
