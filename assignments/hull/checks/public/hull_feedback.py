"""Staged feedback on orientation and convex-hull answers, shared by public and hidden checks.

Everything here is bookkeeping on indices: the caller supplies the expected
hull and the *boundary walk* (every distinct pin on the hull's boundary, in
counter-clockwise order from the expected start), so no geometry happens here.

A hull check calls :func:`grade_hull`; it returns when the answer is right, ends the
check with partial credit when the answer describes the right rubber band but
breaks a convention, and raises ``CheckFailure`` when the band is wrong.
Shape of the feedback: type, then range, then which pins, then their order.
An orientation check calls :func:`judge_turn` for each triple.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

import numpy as np
from numpy.typing import ArrayLike

from autograder.checks import (
    Broken,
    CheckFailure,
    Conventions,
    Credit,
    expect_indices,
    expect_int,
    is_rotation_reversed,
    same_cycle,
    sentence,
    show_point,
)

#: what a right hull keeps of the points for each convention it breaks (multiplied together)
CONVENTIONS = Conventions({
    "closed": 0.75,     # first index repeated at the end
    "start": 0.75,      # right cycle, another starting corner
    "clockwise": 0.5,   # right cycle, walked the other way round
    "collinear": 0.5,   # pins in the middle of an edge kept as corners
})

NAME = "convex_hull(points)"


def canonical_indices(points: np.ndarray) -> np.ndarray:
    """For each pin, the smallest index of a pin at exactly the same place."""
    first: dict[tuple[float, float], int] = {}
    return np.array([first.setdefault((float(x), float(y)), i)
                     for i, (x, y) in enumerate(np.asarray(points, dtype=float))], dtype=int)


def _at(points: np.ndarray, i: int) -> str:
    return f"point {i} at {show_point(points[i])}"


def _as_indices(got: object, n: int) -> list[int]:
    """The answer as a list of valid row indices, or a CheckFailure saying what is wrong."""
    hint = "Return the row numbers of the corner pins, like [2, 1, 4], not their coordinates."
    if isinstance(got, (list, tuple, np.ndarray)) and len(got) == 0:
        raise CheckFailure(f"{NAME} returned an empty list; every set of pins has at least "
                           "one hull corner.")
    return expect_indices(got, n, shape=(None,), name=NAME, hint=hint).tolist()


def _collapse_repeats(walk: list[int]) -> list[int]:
    """Drop a pin that follows itself (cyclically): [a, a, b] -> [a, b]."""
    if len(walk) <= 1:
        return walk
    return [v for k, v in enumerate(walk) if v != walk[k - 1]] or walk[:1]


def judge_hull(got: object, points: ArrayLike, expected: Sequence[int],
               boundary: Sequence[int]) -> Broken:
    """The conventions a right hull answer breaks; raise CheckFailure when it is wrong.

    ``expected`` is the hull in canonical indices (counter-clockwise from the
    lexicographically smallest pin); ``boundary`` lists every distinct pin on
    the hull's boundary in the same order (corners and pins on edges).
    """
    points = np.asarray(points, dtype=float)
    canon = canonical_indices(points)
    hull = _as_indices(got, len(points))
    walk = [int(canon[i]) for i in hull]
    broken = CONVENTIONS.record()

    if len(walk) > 1 and walk[-1] == walk[0]:
        broken.note("closed", f"your list ends with its first corner again (index {hull[-1]}); "
                              "list each corner once, the band closes by itself")
        walk = walk[:-1]
    collapsed = _collapse_repeats(walk)
    if len(collapsed) < len(walk):
        broken.note("collinear", "your list names the same place twice in a row (pins at "
                                 "exactly the same place count once)")
    expected = [int(canon[v]) for v in expected]
    boundary = [int(canon[v]) for v in boundary]
    on_boundary = set(boundary)
    _check_pins(collapsed, expected, on_boundary, points, len(hull))

    extra = list(dict.fromkeys(v for v in collapsed if v not in set(expected)))
    if extra:
        broken.note("collinear", f"your hull keeps {_at(points, extra[0])}, which lies on a hull "
                                 "edge without being a corner; when pins are collinear keep "
                                 "only the farthest" + _how_many(extra, "such pins"),
                    replace=True)
    if len(expected) > 2:
        _check_order(collapsed, [v for v in boundary if v in set(collapsed)], points, broken)
    elif not extra and len(expected) == 2 and collapsed[0] != expected[0]:
        broken.note("start", _start_at(expected[0]))
    return broken


def _how_many(items: Sequence[int], what: str) -> str:
    """`` (3 such pins)`` after a message about the first of several items; nothing for one."""
    return f" ({len(items)} {what})" if len(items) > 1 else ""


def _start_at(index: int) -> str:
    return (f"start at the lexicographically smallest point (index {index}): smallest x, "
            "then smallest y")


def _check_pins(collapsed: list[int], expected: list[int], on_boundary: set[int],
                points: np.ndarray, got_len: int) -> None:
    """Fail when a corner is missing, a pin is off the band, or a pin comes twice."""
    seen = set(collapsed)
    missing = [v for v in expected if v not in seen]
    inside = [v for v in collapsed if v not in on_boundary]
    parts = []
    if missing:
        parts.append(f"{_at(points, missing[0])} is on the hull but missing"
                     + _how_many(missing, "corners are missing"))
    if inside:
        parts.append(f"{_at(points, inside[0])} is not on the hull's boundary, so it is not "
                     "a corner" + _how_many(inside, "such pins"))
    middle = [v for v in collapsed if v in on_boundary and v not in set(expected)]
    if missing and middle:
        parts.append(f"you returned {_at(points, middle[0])}, which lies on the boundary "
                     "between two corners (in the middle of an edge), so it is not a corner"
                     + _how_many(middle, "such pins"))
    if parts:
        raise CheckFailure(sentence(f"Expected {len(expected)} hull vertices, got {got_len}; "
                                    + "; ".join(parts)))
    twice = next((v for v in collapsed if collapsed.count(v) > 1), None)
    if twice is not None and len(expected) > 2:
        raise CheckFailure(sentence(f"{_at(points, twice)} appears {collapsed.count(twice)} "
                                     "times in your hull; the band passes each corner once"))


def _check_order(collapsed: list[int], order: list[int], points: np.ndarray,
                 broken: Broken) -> None:
    """Compare the order with the counter-clockwise boundary walk restricted to the same pins."""
    if collapsed == order:
        return
    if same_cycle(collapsed, order):
        broken.note("start", _start_at(order[0]))
        return
    if is_rotation_reversed(collapsed, order):
        broken.note("clockwise", "your hull is correct but clockwise: list the vertices "
                                 "counter-clockwise (left turns)")
        if collapsed[0] != order[0]:
            broken.note("start", _start_at(order[0]))
        return
    k = collapsed.index(order[0])
    walk = collapsed[k:] + collapsed[:k]
    step = next(i for i in range(1, len(order)) if walk[i] != order[i])
    raise CheckFailure(
        f"Your hull has the right corners but not in order around the band: after "
        f"{_at(points, walk[step - 1])} the next one counter-clockwise is "
        f"{_at(points, order[step])}, not {_at(points, walk[step])}.")


def grade_hull(got: object, points: ArrayLike, expected: Sequence[int],
               boundary: Sequence[int], credit: Credit) -> None:
    """Judge the answer and end the check: pass, ``credit.partial(...)``, or CheckFailure."""
    judge_hull(got, points, expected, boundary).finish(credit)


#: A general pin set, small enough to check by hand: degenerate cases (one pin, pins in
#: one place or on one line) earn points only for a convex_hull that gets it right.
GENERAL_POINTS = np.array([[0.0, 0.0], [4.0, 0.0], [1.0, 1.0], [4.0, 3.0], [2.0, 4.0],
                           [0.0, 3.0], [2.0, 2.0]])
GENERAL_HULL = [0, 1, 3, 4, 5]


def require_general_case(hull: Callable[[np.ndarray], object], what: str) -> None:
    """Fail unless ``hull`` finds the hull of :data:`GENERAL_POINTS` (up to conventions).

    A degenerate case is answered right by many stubs (``return [0]``, a constant list);
    its points are earned only by a function that also solves the general case.
    """
    try:
        judge_hull(hull(GENERAL_POINTS.copy()), GENERAL_POINTS, GENERAL_HULL, GENERAL_HULL)
    except CheckFailure as exc:
        raise CheckFailure(
            f"The {what} earns points only when convex_hull also finds the hull of a "
            f"general set of pins, and on {show_point(GENERAL_POINTS[0])}, ..., "
            f"{show_point(GENERAL_POINTS[-1])} ({len(GENERAL_POINTS)} pins) it does not: "
            f"{exc}") from None


TURN_WORDS = {1: "a left turn (counter-clockwise)", -1: "a right turn (clockwise)",
              0: "no turn (they are collinear)"}


def _signed(value: int) -> str:
    return f"{value:+d}" if value else "0"


#: (p, q, r, sign of the turn): a left and a right turn each, for require_general_turns
GENERAL_TURNS = [((0, 0), (1, 0), (0, 1), 1), ((0, 0), (0, 1), (1, 0), -1),
                 ((1, 1), (4, 2), (2, 5), 1), ((3, 3), (5, 1), (1, 0), -1)]


def require_general_turns(answers: Iterator[object], what: str) -> None:
    """Fail unless orientation gets a left and a right turn right.

    ``answers`` yields orientation's answers on :data:`GENERAL_TURNS` first, in order
    (``student.map("orientation", ...)`` over them and then the check's own triples);
    exactly ``len(GENERAL_TURNS)`` are read. ``return 0`` answers every collinear
    triple; collinear cases are earned only by a function that also tells the two
    turns apart.
    """
    for (p, q, r, expected), got in zip(GENERAL_TURNS, answers):
        try:
            judge_turn(got, p, q, r, expected)
        except CheckFailure as exc:
            raise CheckFailure(f"The {what} earn points only when orientation also tells "
                               f"left turns from right turns, and it does not: {exc}") from None


def judge_turn(got: object, p: ArrayLike, q: ArrayLike, r: ArrayLike, expected: int, *,
               hint: str = "") -> None:
    """Raise CheckFailure unless ``got`` is the integer ``expected`` (+1, -1 or 0)."""
    call = f"orientation({show_point(p)}, {show_point(q)}, {show_point(r)})"
    value = expect_int(got, name=call)
    if value not in (-1, 0, 1):
        raise CheckFailure(f"{call} returned {value}; return only the sign of the "
                           "determinant: +1, -1 or 0.")
    if value != expected:
        raise CheckFailure(f"{call} returned {_signed(value)}; expected {_signed(expected)}: "
                           f"the points make {TURN_WORDS[expected]}."
                           + (f" {hint}" if hint else ""))
