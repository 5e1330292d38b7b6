"""Course-specific judging in the assignments' public helpers, against answers built to game it."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from autograder.errors import CheckFailure

ROOT = Path(__file__).resolve().parents[2]


def helper(assignment: str, module: str) -> ModuleType:
    """Import ``assignments/<assignment>/checks/public/<module>.py`` as checks do."""
    public = ROOT / "assignments" / assignment / "checks" / "public"
    sys.path.insert(0, str(public))
    try:
        spec = importlib.util.spec_from_file_location(module, public / f"{module}.py")
        assert spec is not None and spec.loader is not None
        loaded = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(loaded)
        return loaded
    finally:
        sys.path.remove(str(public))


class Credit:
    def __init__(self) -> None:
        self.given: list[tuple[float, str]] = []

    def partial(self, fraction: float, message: str) -> None:
        self.given.append((fraction, message))


def runge(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + 16.0 * np.asarray(x, dtype=float) ** 2)


def test_a_line_through_the_nodes_only_is_not_the_interpolant() -> None:
    """f drawn at the 13 nodes, repeated to look like a long line, must not pass as the
    degree-12 interpolant: every interpolant equals f at its nodes."""
    fb = helper("interpolation", "interp_feedback")
    nodes = np.linspace(-1, 1, 13)
    fine = np.linspace(-1, 1, 400)
    tiled = np.tile(nodes, 6)
    figure = {"axes": [{"lines": [{"x": fine.tolist(), "y": runge(fine).tolist()},
                                  {"x": tiled.tolist(), "y": runge(tiled).tolist()}]}]}
    from scipy.interpolate import BarycentricInterpolator
    interpolant = BarycentricInterpolator(nodes, runge(nodes))
    wanted = [fb.Curve("Runge's function", runge), fb.Curve("the equispaced interpolant", interpolant)]
    credit = Credit()
    try:
        fb.judge_runge_plot(figure, call="plot_runge(12)", wanted=wanted, credit=credit)
    except CheckFailure:
        pytest.fail("Runge's function itself is drawn: half the points are earned")
    assert [round(f, 6) for f, _ in credit.given] == [0.5]
    assert "could not find the equispaced interpolant" in credit.given[0][1]

    drawn = {"axes": [{"lines": [{"x": fine.tolist(), "y": runge(fine).tolist()},
                                 {"x": fine.tolist(), "y": interpolant(fine).tolist()}]}]}
    honest = Credit()
    fb.judge_runge_plot(drawn, call="plot_runge(12)", wanted=wanted, credit=honest)
    assert honest.given == [], "the honest plot earns everything"
