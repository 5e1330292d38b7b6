"""Staged feedback on spline answers, shared by the public and the hidden checks.

Coefficients are judged in stages, each with a message that says what is wrong
and where: the type and shape of the array, the layout of each row (SciPy's
order [d, c, b, a] or a transposed array is recognised and earns part of the
points), then the defining properties of the natural cubic spline (passes
through the points; S, S' and S'' continuous at every interior knot;
S'' = 0 at both ends), and only then the values against the expected ones.
The properties are read from the coefficients themselves, so a check can say
*which* property fails, not only that a number differs.

Drawings are judged by the distance between the drawn points and the
reference drawing (:mod:`autograder.checks.compare_curves`), with the two pictures attached
side by side. The reference drawing is made here, with SciPy's natural
``CubicSpline`` in the chord-length parameter (the model solution is not
part of a student's install, so released helpers never import it).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline

from autograder.checks import (
    CheckFailure,
    Conventions,
    Credit,
    Feedback,
    FigureData,
    describe,
    expect_array,
    expect_close,
    expect_figure,
    is_figure,
    show_number,
    side_by_side,
)
from autograder.checks.compare_curves import CurveDistance, curve_points, hausdorff, relative_curve_distance

if TYPE_CHECKING:
    from matplotlib.axes import Axes

NAME = "spline_coefficients(x, y)"

#: Fraction of a check's points kept when the spline is right but a convention is
#: not: the mathematics is done, the interface is not.
CONVENTIONS = Conventions({
    "layout": 0.5,       # coefficients in SciPy's order, or transposed
    "eval-order": 0.5,   # spline_eval reads each row as [d, c, b, a]
    "aspect": 0.75,      # a right drawing whose axes do not have equal aspect
})
#: Significant digits of the numbers in messages (never rounded into an integer they are not).
DIGITS = 4

SCIPY_ROWS = ("your coefficients are right but in SciPy's order [d, c, b, a]; "
              "the assignment asks for [a, b, c, d]")
SCIPY_C = ("your coefficients are right but laid out like SciPy's `c` array (shape "
           "(4, n-1), rows d, c, b, a); the assignment asks for shape (n-1, 4) with one "
           "row [a, b, c, d] per piece")
TRANSPOSED = ("your coefficients are right but transposed: shape (4, n-1) instead of "
              "(n-1, 4); the assignment asks for one row [a, b, c, d] per piece")

#: Drawings: the relative Hausdorff distance (a fraction of the reference's
#: bounding-box diagonal) allowed for full points, and for half the points.
#: A correct drawing sampled at 200 points per stroke is within 0.001 of the
#: reference and a coarse one (30 points per stroke) within 0.008; 0.02 of the
#: car's diagonal (0.2 units) is where a difference starts to be visible.
DRAWING_PASS = 0.02
DRAWING_HALF = 0.08
#: Points per stroke sampled along the reference drawing (dense: the sampling
#: gap must stay far below DRAWING_PASS).
REFERENCE_SAMPLES = 2000


# ---------------------------------------------------------------------------
# reading the coefficient array
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Reading:
    """The student's coefficients as rows [a, b, c, d], and the convention they broke."""

    rows: np.ndarray
    convention: str | None = None


def read_coefficients(got: object, x: np.ndarray, y: np.ndarray, *, name: str = NAME) -> Reading:
    """Interpret ``got`` as ``(n-1, 4)`` rows [a, b, c, d], recognising SciPy's layouts.

    Among the layouts that fit the shape, the one whose ``a`` column equals
    ``y[:-1]`` (every piece starts at its data point) is chosen; if none does,
    the layout the assignment asks for.
    """
    arr = expect_array(got, dtype_kind="biuf", name=name).astype(float)
    pieces = len(x) - 1
    layouts: list[tuple[np.ndarray, str | None]] = []
    if arr.shape == (pieces, 4):
        layouts += [(arr, None), (arr[:, ::-1], SCIPY_ROWS)]
    if arr.shape == (4, pieces):
        layouts += [(arr.T[:, ::-1], SCIPY_C), (arr.T, TRANSPOSED)]
    if not layouts:
        raise CheckFailure(_shape_message(arr.shape, pieces, name))
    bad = ~np.isfinite(arr)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise CheckFailure(f"{name} contains {arr[where]} at index {list(where)}; every "
                           "coefficient should be a finite number. Look for a division by "
                           "zero (are the gaps h_i right?) or an unsolved system.")
    scale = float(np.max(np.abs(y))) or 1.0
    for rows, convention in layouts:
        if np.allclose(rows[:, 0], y[:-1], rtol=1e-9, atol=1e-12 * scale):
            return Reading(np.ascontiguousarray(rows), convention)
    return Reading(np.ascontiguousarray(layouts[0][0]), layouts[0][1])


def _shape_message(shape: tuple[int, ...], pieces: int, name: str) -> str:
    text = (f"{name} should return an array of shape (len(x) - 1, 4) = ({pieces}, 4): one row "
            f"[a, b, c, d] for each of the {pieces} piece(s); got shape {shape}.")
    if shape == (pieces + 1, 4):
        text += (" That is one row too many: len(x) points make len(x) - 1 pieces "
                 "(the last point only ends the last piece).")
    elif len(shape) == 1 and shape[0] == 4 * pieces:
        text += " Stack the rows into a 2-D array, e.g. np.column_stack([a, b, c, d])."
    elif len(shape) == 2 and 4 in shape:
        text += f" Each row is one piece; there are {pieces} pieces."
    return text


def finish(reading: Reading, credit: Credit) -> None:
    """End a check whose mathematics passed: full points, or part for a broken convention."""
    if reading.convention is not None:
        CONVENTIONS.partial(credit, "layout", reading.convention)


def _convention_note(reading: Reading) -> str:
    if reading.convention is None:
        return ""
    return f"(Note: your array was read as rows [a, b, c, d] after reordering: " \
           f"{reading.convention}.)"


def _with_convention(message: str, reading: Reading) -> str:
    return f"{message} {_convention_note(reading)}".rstrip()


# ---------------------------------------------------------------------------
# properties of a natural cubic spline, read from its coefficients
# ---------------------------------------------------------------------------

def knot_values(rows: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """S, S', S'' at the left end (``x[i]``) and right end (``x[i+1]``) of each piece.

    Returns two arrays of shape (3, n-1): row k is the k-th derivative.
    """
    a, b, c, d = rows.T
    h = np.diff(x)
    left = np.stack([a, b, 2.0 * c])
    right = np.stack([a + h * (b + h * (c + h * d)), b + h * (2.0 * c + 3.0 * h * d),
                      2.0 * c + 6.0 * h * d])
    return left, right


def _scales(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Size of S, S', S'' near each knot: max|y| / h**k with h the smaller neighbouring gap."""
    h = np.diff(x)
    near = np.minimum(np.r_[h, np.inf], np.r_[np.inf, h])  # at each knot
    size = float(np.max(np.abs(y))) or 1.0
    return np.stack([np.full_like(near, size), size / near, size / near**2])


def check_passes_through(reading: Reading, x: np.ndarray, y: np.ndarray, rtol: float) -> None:
    """Piece i starts at (x[i], y[i]) and ends at (x[i+1], y[i+1])."""
    left, right = knot_values(reading.rows, x)
    tol = rtol * _scales(x, y)[0]
    start_err = np.abs(left[0] - y[:-1])
    if np.any(start_err > tol[:-1]):
        i = int(np.argmax(start_err - tol[:-1]))
        raise CheckFailure(_with_convention(
            f"Your spline does not pass through the data: piece {i} (on [x[{i}], x[{i + 1}]]) "
            f"starts at S({show_number(x[i], DIGITS)}) = a = "
            f"{show_number(left[0, i], DIGITS)}, but y[{i}] = {show_number(y[i], DIGITS)}. "
            f"Row i must start with a = y[i].", reading))
    end_err = np.abs(right[0] - y[1:])
    if np.any(end_err > tol[1:]):
        i = int(np.argmax(end_err - tol[1:]))
        raise CheckFailure(_with_convention(
            f"Your spline does not pass through the data: piece {i} ends at "
            f"S({show_number(x[i + 1], DIGITS)}) = a + b h + c h^2 + d h^3 = "
            f"{show_number(right[0, i], DIGITS)} (h = x[{i + 1}] - x[{i}]), but "
            f"y[{i + 1}] = {show_number(y[i + 1], DIGITS)}. Check b "
            "(it depends on the slope (y[i+1] - y[i]) / h[i] and on M) and d.", reading))


_DERIVATIVE = {0: ("S", "value"), 1: ("S'", "first derivative (slope)"),
               2: ("S''", "second derivative")}
_JUMP_HINT = {
    0: " Each piece must end where the next one starts: check b and d.",
    1: " A piecewise linear interpolant, or pieces fitted one at a time, has this problem: "
       "the pieces must be tied together by the tridiagonal system for M.",
    2: " Check the formulas for b, c and d in terms of M: S''(x_i) = 2c_i must equal M_i "
       "from both sides.",
}


def check_continuity(reading: Reading, x: np.ndarray, y: np.ndarray, rtol: float) -> None:
    """S, S' and S'' agree from both sides at every interior knot."""
    left, right = knot_values(reading.rows, x)
    scales = _scales(x, y)
    for k in (0, 1, 2):
        jump = np.abs(right[k, :-1] - left[k, 1:])  # at interior knots x[1] .. x[n-2]
        tol = rtol * scales[k, 1:-1]
        if np.any(jump > tol):
            j = int(np.argmax(jump / tol)) + 1
            symbol, words = _DERIVATIVE[k]
            raise CheckFailure(_with_convention(
                f"The {words} of your spline jumps at the interior knot x[{j}] = "
                f"{show_number(x[j], DIGITS)}: the piece on its left ends with {symbol} = "
                f"{show_number(right[k, j - 1], DIGITS)}, the piece on its right starts with "
                f"{symbol} = {show_number(left[k, j], DIGITS)}. A cubic spline has "
                f"continuous S, S' and S'' at every interior knot.{_JUMP_HINT[k]}", reading))


def check_natural_ends(reading: Reading, x: np.ndarray, y: np.ndarray, rtol: float) -> None:
    """S''(x[0]) = 0 and S''(x[n-1]) = 0; a clamped spline (zero end slopes) is named."""
    left, right = knot_values(reading.rows, x)
    scales = _scales(x, y)
    ends = (("left", left[2, 0], scales[2, 0], "x_0"),
            ("right", right[2, -1], scales[2, -1], "x_n"))
    for side, value, scale, symbol in ends:
        if abs(value) > rtol * scale:
            clamped = (abs(left[1, 0]) <= rtol * scales[1, 0]
                       and abs(right[1, -1]) <= rtol * scales[1, -1])
            hint = ("Your spline has zero slope at both ends instead: that is the clamped "
                    "spline, S'(x_0) = S'(x_n) = 0." if clamped else
                    "Check the first and last rows of your system (or how you set M_0 and M_n).")
            raise CheckFailure(_with_convention(
                f"The second derivative of your spline is not zero at the {side} end "
                f"(S''({symbol}) = {value:.1e}). Natural end conditions set M_0 = S''(x_0) = 0 "
                f"and M_n = S''(x_n) = 0. {hint}", reading))


def check_values(reading: Reading, expected: np.ndarray, rtol: float) -> None:
    """Each coefficient within ``rtol * (|expected| + largest |expected| in its column)``."""
    want = np.asarray(expected, dtype=float)
    expect_close(reading.rows, want, rtol=rtol, atol=rtol * np.max(np.abs(want), axis=0),
                 name=NAME, at=lambda i: f"coefficient {'abcd'[i[1]]} of piece {i[0]} "
                                         f"(row {i[0]}, column {i[1]})",
                 hint=_convention_note(reading))


def grade_coefficients(got: object, x: np.ndarray, y: np.ndarray, expected: np.ndarray,
                       credit: Credit, *, rtol: float) -> None:
    """All stages: layout, passes through the points, C2, natural ends, values."""
    reading = read_coefficients(got, x, y)
    check_passes_through(reading, x, y, rtol)
    check_continuity(reading, x, y, rtol)
    check_natural_ends(reading, x, y, rtol)
    check_values(reading, expected, rtol)
    finish(reading, credit)


# ---------------------------------------------------------------------------
# spline_eval
# ---------------------------------------------------------------------------

def where_is(t: float, x: np.ndarray) -> str:
    """Where ``t`` lies among the knots, for a message."""
    hits = np.flatnonzero(x == t)
    if hits.size:
        return f"the knot x[{int(hits[0])}]"
    if t < x[0]:
        return "left of x[0] (use the first piece there)"
    if t > x[-1]:
        return f"right of x[{len(x) - 1}] (use the last piece there)"
    i = int(np.searchsorted(x, t, side="right")) - 1
    return f"between x[{i}] and x[{i + 1}] (piece {i})"


def grade_eval(got: object, x: np.ndarray, t: np.ndarray, expected: np.ndarray, *,
               rtol: float, credit: Credit,
               retry_reversed: Callable[[], object] | None = None) -> None:
    """Compare ``spline_eval`` values with the expected ones, saying where they differ.

    If they differ and ``retry_reversed`` is given, it is called (it should
    evaluate with every row reversed): when that matches, the student's
    function reads rows as [d, c, b, a], which earns part of the points.
    """
    name = "spline_eval(x, coeffs, t)"
    want = np.asarray(expected, dtype=float)
    arr = expect_array(got, dtype_kind="biuf", name=name)
    if arr.shape != want.shape:
        raise CheckFailure(f"{name} should return one value per entry of t, an array of shape "
                           f"{want.shape}; got {describe(got)}.")
    atol = rtol * (float(np.max(np.abs(want))) or 1.0)
    try:
        expect_close(arr, want, rtol=rtol, atol=atol, name=name,
                     at=lambda i: f"t = {show_number(t[i], DIGITS)}, {where_is(float(t[i]), x)}",
                     hint="Find the piece i with x[i] <= t < x[i+1] and evaluate "
                          "a + b u + c u^2 + d u^3 with u = t - x[i] (not t).")
    except CheckFailure:
        if retry_reversed is not None:
            again = np.asarray(retry_reversed(), dtype=float)
            if again.shape == want.shape and np.all(np.abs(again - want)
                                                    <= atol + rtol * np.abs(want)):
                CONVENTIONS.partial(credit, "eval-order",
                                    "Your spline_eval reads each row of coeffs as [d, c, b, a] "
                                    "(SciPy's order); the assignment's rows are [a, b, c, d], "
                                    "with S_i(t) = a + b (t - x_i) + c (t - x_i)^2 + "
                                    "d (t - x_i)^3.")
        raise


# ---------------------------------------------------------------------------
# drawings
# ---------------------------------------------------------------------------

UNIFORM_HINT = ("Use the chord length instead: s_0 = 0, s_k = s_(k-1) + |P_k - P_(k-1)|, so "
                "that short and long steps between points get short and long stretches of "
                "parameter.")


def stroke_spline(stroke: np.ndarray, *, parametrization: str = "chord",
                  bc_type: str = "natural") -> CubicSpline:
    """The parametric cubic spline through a stroke's points: x(s) and y(s) in one spline.

    ``s`` is the chord length (``s_k = s_(k-1) + |P_k - P_(k-1)|``) or, for
    ``parametrization="uniform"``, the point number; points that repeat the one
    before them are dropped (they would make two equal knots).
    """
    pts = np.asarray(stroke, dtype=float)
    steps = np.hypot(*np.diff(pts, axis=0).T)
    pts = np.concatenate([pts[:1], pts[1:][steps > 0]])
    steps = steps[steps > 0] if parametrization == "chord" else np.ones(int(np.sum(steps > 0)))
    if len(pts) < 2:
        raise ValueError("a stroke needs two distinct points")
    s = np.concatenate([[0.0], np.cumsum(steps)])
    return CubicSpline(s, pts, bc_type=bc_type)


def sample_strokes(strokes: Sequence[np.ndarray], num: int = REFERENCE_SAMPLES,
                   **options: str) -> np.ndarray:
    """``num`` points along each stroke's spline (see :func:`stroke_spline`), stacked."""
    parts: list[np.ndarray] = []
    for stroke in strokes:
        spline = stroke_spline(stroke, **options)
        parts.append(spline(np.linspace(spline.x[0], spline.x[-1], num)))
    return np.concatenate(parts)


def draw_reference(strokes: Sequence[np.ndarray]) -> Callable[[Axes], None]:
    """A function that draws the reference car (or shape) on a matplotlib ``Axes``."""
    def draw(ax: Axes) -> None:
        for stroke in strokes:
            curve = sample_strokes([stroke], 200)
            ax.plot(curve[:, 0], curve[:, 1], "-", color="k", linewidth=2,
                    solid_capstyle="round")
        ax.set_aspect("equal")
    return draw


def _alternatives(strokes: Sequence[np.ndarray]) -> dict[str, Callable[[], np.ndarray]]:
    """Typical wrong drawings of ``strokes`` and the hint each one deserves."""
    def drawn(**options: str) -> Callable[[], np.ndarray]:
        return lambda: sample_strokes(strokes, **options)

    def polyline() -> np.ndarray:
        t = np.linspace(0.0, 1.0, 50)[:-1, None]
        parts = [np.concatenate([a + t * (b - a) for a, b in zip(s[:-1], s[1:])] + [s[-1:]])
                 for s in strokes]
        return np.concatenate(parts)

    return {
        "Your curves match splines drawn with the point number as the parameter (s_k = k). "
        + UNIFORM_HINT: drawn(parametrization="uniform"),
        "Your curves look like straight lines between the points: draw each stroke as the "
        "two splines x(s) and y(s), sampled at many values of s (e.g. 200).": polyline,
        "Your curves match splines with zero slope at their ends; use natural end conditions "
        "(S'' = 0 at both ends).": drawn(bc_type="clamped"),
    }


def grade_drawing(fig: object, strokes: Sequence[np.ndarray], credit: Credit, feedback: Feedback,
                  *, what: str = "car", name: str = "draw_car(strokes)",
                  picture_shown: bool = True) -> None:
    """Judge a drawing of ``strokes`` and attach it beside the reference.

    Full points when the relative Hausdorff distance is at most
    ``DRAWING_PASS`` (and the axes have equal aspect), half up to
    ``DRAWING_HALF``, none beyond; messages say what is missing or extra.
    ``picture_shown`` is False for hidden checks: their pictures (of unseen
    data) never reach the student, so the message does not mention them.
    """
    strokes = [np.asarray(s, dtype=float) for s in strokes]
    feedback.image(f"your {what} beside the reference", side_by_side(
        fig if is_figure(fig) else None, draw_reference(strokes),
        title=f"{name}: your drawing (left) and the reference (right)"))
    figure = expect_figure(fig, name=name)
    points = curve_points(figure)
    if len(points) == 0:
        raise CheckFailure(f"The figure returned by {name} has no curves on it. Draw each "
                           "stroke with ax.plot on the axes of the figure you return.")
    reference = sample_strokes(strokes)
    dist = relative_curve_distance(points, reference)
    mistake = _known_mistake(figure, strokes, reference, dist.scale)
    if mistake:
        message = (f"Your {what} follows the wrong curve: {mistake}"
                   + (" Compare the two pictures attached." if picture_shown else ""))
        if dist.worst <= DRAWING_HALF:
            credit.partial(0.5, message)
        raise CheckFailure(message)
    if dist.worst <= DRAWING_PASS:
        if not any(ax.get("aspect") == "equal" for ax in figure["axes"] if isinstance(ax, dict)):
            CONVENTIONS.partial(credit, "aspect",
                                f"Your {what} is right, but the axes do not have equal aspect, "
                                "so circles look like ellipses: call ax.set_aspect('equal').")
        return
    far = f"{dist.worst:.1%} of" if dist.worst < 1.0 else f"{dist.worst:.3g} times"
    message = (f"Your drawing is {far} the {what}'s size (the diagonal of its "
               f"bounding box, {dist.scale:.3g} units) away from the reference; up to "
               f"{DRAWING_PASS:.0%} is allowed: {dist.gaps(what, DRAWING_PASS)}."
               + (" Compare the two pictures attached." if picture_shown else ""))
    hint = _diagnose(points, strokes, dist)
    if hint:
        message += " " + hint
    if dist.worst <= DRAWING_HALF:
        credit.partial(0.5, message)
    raise CheckFailure(message)


#: A drawing *is* a known mistake when the points it drew (its vertices, which lie
#: on the student's own curve whatever the sampling) stray from the reference by more
#: than MISTAKE_FLOOR of the diagonal while lying on the mistake's curve (within
#: MISTAKE_FLOOR / 2, and MISTAKE_RATIO times closer to it). Measured over 60 unseen
#: shapes of each kind and 30 to 300 points per stroke: correct drawings stray at most
#: 0.0006, uniform-parameter drawings at least 0.0094 while lying within 0.0012 of
#: the uniform curve; so neither decision depends on the student's seed.
MISTAKE_FLOOR = DRAWING_PASS / 4
MISTAKE_RATIO = 4.0


def _known_mistake(fig: FigureData, strokes: Sequence[np.ndarray], reference: np.ndarray,
                   scale: float) -> str:
    """The hint of a penalised mistake (the point number as parameter) the drawing makes."""
    vertices = curve_points(fig, samples_per_segment=1)
    stray = hausdorff(vertices, reference)[0] / scale
    if len(vertices) == 0 or stray <= MISTAKE_FLOOR:
        return ""
    uniform = sample_strokes(strokes, 4 * REFERENCE_SAMPLES, parametrization="uniform")
    on_uniform = hausdorff(vertices, uniform)[0] / scale
    if on_uniform <= MISTAKE_FLOOR / 2 and on_uniform * MISTAKE_RATIO < stray:
        return (f"its points lie up to {stray:.1%} of the drawing's size off the "
                "reference, on the splines drawn with the point number as the parameter "
                "(s_k = k). " + UNIFORM_HINT)
    return ""


def _diagnose(points: np.ndarray, strokes: Sequence[np.ndarray], dist: CurveDistance) -> str:
    """The hint of the typical mistake the drawing matches, if it measurably matches one."""
    for hint, build in _alternatives(strokes).items():
        try:
            other = relative_curve_distance(points, build())
        except ValueError:
            continue
        if other.worst <= DRAWING_PASS / 2 and other.worst < dist.worst / 2:
            return hint
    return ""
