"""Every student their own board of pins (the ``[variants]`` hook of the hull assignment).

Runs on the grader's side only (release, grading, the service's download); this file
is never released. ``draw(rng)`` gives a student's ``pins`` from their seed;
``answers(params)`` gives the hull of those pins, so a submission whose hull is a
classmate's (an answer that travelled) is seen.

A fair board: every student's problem has the features of the instructor's board
(``data/pins.csv``: 31 pins, 8 corners, 2 pins in the middle of hull edges), so
each known mistake costs the same on every board:

* 31 distinct pins (no duplicates: the instructor's board has none) on the
  quarter-centimetre grid of the same board, x in [1, 9.5] and y in [0.5, 7.5];
  the coordinates are short dyadic numbers, exact in binary, so collinear pins
  are exactly collinear and the hull is unique;
* 7 to 9 corners (not a triangle, not nearly every pin on the band);
* 1 or 2 pins in the middle of a hull edge (a march that keeps collinear pins
  loses the same half on every board; the notebook tells every student to look
  for one);
* one pin alone at the smallest x (where the list must start is decided by x,
  never by the tie-break on y, on every board).

Boards are drawn uniformly on the grid and redrawn until they have all four
features; about one in six has them, so a few draws suffice (the bound of 2000
is never reached: it would take a chance below 1e-150). The draw depends only
on the seed, so release, grading and regrading agree.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from reference import convex_hull, orient2d

N_PINS = 31
STEP = 0.25                      # the grid, in centimetres
X_CELLS = range(4, 39)           # x = 1.0 ... 9.5 in steps of 0.25
Y_CELLS = range(2, 31)           # y = 0.5 ... 7.5
CORNERS = range(7, 10)
EDGE_PINS = range(1, 3)
MAX_DRAWS = 2000


def edge_pins(points: np.ndarray, hull: list[int]) -> int:
    """How many pins lie in the middle of a hull edge (on it, not a corner)."""
    count = 0
    for a, b in zip(hull, hull[1:] + hull[:1]):
        lo, hi = np.minimum(points[a], points[b]), np.maximum(points[a], points[b])
        count += sum(1 for i in range(len(points)) if i not in (a, b)
                     and np.all(lo <= points[i]) and np.all(points[i] <= hi)
                     and orient2d(points[a], points[b], points[i]) == 0)
    return count


def is_fair(points: np.ndarray) -> bool:
    """Whether a board has the features every board has (see the module's docstring)."""
    hull = [int(i) for i in convex_hull(points)]
    alone_at_left = int(np.sum(points[:, 0] == points[:, 0].min())) == 1
    return (len(np.unique(points, axis=0)) == len(points) and len(hull) in CORNERS
            and alone_at_left and edge_pins(points, hull) in EDGE_PINS)


def draw(rng: np.random.Generator) -> dict[str, Any]:
    cells = np.array([(x, y) for x in X_CELLS for y in Y_CELLS], dtype=float)
    for _ in range(MAX_DRAWS):
        points = cells[rng.choice(len(cells), size=N_PINS, replace=False)] * STEP
        if is_fair(points):
            return {"pins": points.tolist()}
    raise RuntimeError(f"no fair board in {MAX_DRAWS} draws: widen the ranges above")


def answers(params: dict[str, Any]) -> dict[str, Any]:
    """The hull of the student's pins: what their `convex_hull(pins)` must return."""
    return {"pins_hull": [int(i) for i in convex_hull(np.array(params["pins"], dtype=float))]}
