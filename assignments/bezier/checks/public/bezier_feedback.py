"""Staged feedback on Bezier answers, shared by the public and the hidden checks.

Two kinds of answer are judged here:

* a **point** on the curve, from ``eval_bezier(ctrl, t)`` or ``de_casteljau(ctrl, t)``:
  type, then shape (one point of shape ``(d,)``, not a row ``(1, d)`` nor the
  whole triangle of levels), then finite values, then the values themselves;
  at ``t = 0`` and ``t = 1`` the endpoint checks also ask for exact equality
  with the first and last control points;
* the two **control polygons** from ``split_bezier(ctrl, t)``: a pair of
  ``(n + 1, d)`` arrays, checked against the expected polygons, then against
  the known slips (pieces swapped, a piece listed backwards), and when the
  answer is wrong the message goes in stages: ends of the pieces, the cut
  point, then the shape of each piece along the curve.

A judge returns when the answer is right, notes a broken convention in a
:class:`~autograder.checks.Broken` record (which ends the check with partial
credit once every case was looked at), and raises ``CheckFailure`` when the
answer is wrong.

The caller computes the expected values; the only curve evaluation done here
is :func:`curve_points`, an independent oracle (``scipy.interpolate.BPoly``,
fine up to degree 40 or so) used to describe where a student's polygon goes.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy.interpolate import BPoly

from autograder.checks import (
    Broken,
    CheckFailure,
    Conventions,
    Credit,
    Student,
    describe,
    expect_array,
    expect_close,
    explain_errors,
    render_png,
    show_number,
    show_point,
)
from autograder.errors import CallTimeout

#: Share of a check's points kept for each convention broken (multiplied together).
CONVENTIONS = Conventions({
    "levels": 0.5,       # de_casteljau returned the whole triangle; its last level is right
    "row": 0.5,          # the right point, as an array of shape (1, d) instead of (d,)
    "inexact-end": 0.5,  # the first/last control point up to rounding, not exactly
    "swapped": 0.5,      # split_bezier returned (right, left)
    "reversed": 0.5,     # a piece's control points listed from its end back to its start
})

#: How to get the endpoints exactly, per function (shown when they are off by rounding).
EXACT_HINTS = {
    "eval_bezier": (
        "At t = 0 every Bernstein weight is exactly 0 except B_{0,n}(0) = 1, and at t = 1 "
        "every one is 0 except B_{n,n}(1) = 1. Compute t**i and (1 - t)**(n - i) with ** "
        "(0.0 ** 0 is 1.0), not through exp and log, and nothing is rounded."),
    "de_casteljau": (
        "Write each step as (1 - t) * P + t * Q: at t = 1 it gives Q exactly. The form "
        "P + t * (Q - P) is the same in exact arithmetic, but with floats P + (Q - P) can "
        "differ from Q in the last bit."),
}

#: Degree of the probe that tells an exponential recursion (2**20 calls: seconds) from a
#: slow but polynomial loop (210 interpolations: instant), and its time limit in seconds.
PROBE_DEGREE = 20
PROBE_TIMEOUT = 5.0

#: Hints for a call that ran out of time, each shown only when its symptom is measured.
NEVER_ENDS = ("It does not return even for a single control point (degree 0), where the "
              "curve is that point for every t: check that your loop over the levels ends "
              "(n = len(ctrlpts) - 1 levels, none when n = 0).")
EXPONENTIAL = ("It also runs out of time at degree 20, where the de Casteljau triangle has "
               "only 210 interpolations: your function does far more work than that, like a "
               "recursion that calls itself twice per step (about 2**n calls). Build the "
               "triangle level by level instead, each level one numpy expression on the "
               "previous one.")
SLOW_LOOP = ("It returns at small degrees, so the work grows too fast with n: at degree "
             "{n} the triangle has n (n + 1) / 2 = {work:,} interpolations. Compute each "
             "level with one numpy expression ((1 - t) * P[:-1] + t * P[1:]) instead of a "
             "Python loop over its points.")


#: How the right pieces of the triangle make the two control polygons.
SPLIT_HINT = ("The left control points are the first points of the de Casteljau levels, "
              "P_0^(0), P_0^(1), ..., P_0^(n); the right ones are the last points, read from "
              "the apex back down: P_0^(n), P_1^(n-1), ..., P_n^(0).")


# ---------------------------------------------------------------------------
# writing numbers and calls
# ---------------------------------------------------------------------------

#: Significant digits when showing values that are compared with a tolerance.
DIGITS = 12


def show_polygon(ctrl: np.ndarray) -> str:
    """Short polygons in full; longer ones by their degree and dimension."""
    ctrl = np.asarray(ctrl, dtype=float)
    if len(ctrl) <= 4 and ctrl.shape[1] <= 3:
        return "[" + ", ".join(show_point(p) for p in ctrl) + "]"
    return f"<degree-{len(ctrl) - 1} polygon in {ctrl.shape[1]}-D>"


def call_text(fn: str, ctrl: np.ndarray, t: float) -> str:
    return f"{fn}(ctrl, {show_number(t)}) with ctrl = {show_polygon(ctrl)}"


def size(ctrl: np.ndarray) -> float:
    """The scale of a polygon, for tolerances relative to it: max |coordinate|, at least 1."""
    return max(1.0, float(np.max(np.abs(ctrl))))


# ---------------------------------------------------------------------------
# calling the student
# ---------------------------------------------------------------------------

def ask(student: Student, fn: str, ctrl: np.ndarray, t: float, *, hint: str = "",
        timeout: float | None = None) -> object:
    """``student.<fn>(ctrl, t)``; overflow, time-outs and deep recursion come back explained.

    Other exceptions of the student's code pass through (the plugin reports them
    with the traceback), and so do these when there is no ``hint``.
    """
    known = ("OverflowError", "ZeroDivisionError", "RecursionError")
    try:
        with explain_errors(call_text(fn, ctrl, t), dict.fromkeys(known, hint) if hint else {},
                            traceback=True):
            value, _ = student.call(fn, ctrl, float(t), timeout=timeout)
        return value
    except CallTimeout:
        raise CheckFailure(
            f"{call_text(fn, ctrl, t)} did not return within the time limit (degree "
            f"{len(ctrl) - 1}). {timeout_hint(student, fn, ctrl, t)}".rstrip()) from None


def timeout_hint(student: Student, fn: str, ctrl: np.ndarray, t: float) -> str:
    """Why ``fn`` may have run out of time, from what it does on smaller polygons.

    The hint is measured, never guessed from the dataset: a single control point
    that also times out is a loop that never ends; degree 20 timing out is
    exponential work; otherwise the work is polynomial but too slow.
    """
    n = len(ctrl) - 1

    def returns(degree: int) -> bool | None:
        try:
            student.call(fn, ctrl[:degree + 1].copy(), float(t), timeout=PROBE_TIMEOUT)
        except CallTimeout:
            return False
        except Exception:  # another error, or the call was refused: say nothing
            return None
        return True

    if n == 0 or returns(0) is False:
        return NEVER_ENDS
    if n > PROBE_DEGREE:
        probe = returns(PROBE_DEGREE)
        if probe is False:
            return EXPONENTIAL
        if probe is True:
            return SLOW_LOOP.format(n=n, work=n * (n + 1) // 2)
    return ""


# ---------------------------------------------------------------------------
# a point on the curve
# ---------------------------------------------------------------------------

def _levels_shape_ok(item: object, rows: int, d: int, point_ok: bool) -> bool:
    try:
        arr = np.asarray(item, dtype=float)
    except (TypeError, ValueError):
        return False
    return arr.shape == (rows, d) or (point_ok and arr.shape == (d,))


def _is_triangle(got: object, n: int, d: int) -> bool:
    """Whether ``got`` is the list of levels [(n+1, d), (n, d), ..., (1, d)].

    The last level may also be a bare point (d,), except at degree 0, where
    ``[[x, y]]`` is one point written as a row rather than a list of levels.
    """
    if not isinstance(got, (list, tuple)) or len(got) != n + 1:
        return False
    if not all(isinstance(item, (list, tuple, np.ndarray)) for item in got):
        return False
    return all(_levels_shape_ok(item, n + 1 - r, d, point_ok=(r == n and n > 0))
               for r, item in enumerate(got))


def as_point(got: object, *, fn: str, call: str, n: int, d: int,
             broken: Broken) -> tuple[np.ndarray, str]:
    """The answer as a float point of shape (d,); notes a shape convention broken.

    Returns the point and a note to append to a value message ("" or where the
    point was taken from).
    """
    if _is_triangle(got, n, d):
        arrays = f"{n + 1} array{'s' if n else ''}"
        broken.note("levels", (
            f"{fn} should return the point on the curve, shape ({d},); you returned the whole "
            f"triangle of levels (a list of {arrays}). Return only the single point of the "
            "last level."))
        return np.asarray(got[-1], dtype=float).reshape(d), " (the last level you returned)"
    if isinstance(got, (list, tuple)) and got and all(isinstance(g, np.ndarray) for g in got) \
            and len({np.shape(g) for g in got}) > 1:
        raise CheckFailure(
            f"{call} should return one point, an array of shape ({d},); got a list of "
            f"{len(got)} arrays of shapes {', '.join(str(np.shape(g)) for g in got[:4])}"
            f"{', ...' if len(got) > 4 else ''}.")
    arr = expect_array(got, dtype_kind="iuf", name=call)
    if arr.shape == (1, d):
        where = ("the single point of the last level, not the level itself"
                 if fn == "de_casteljau" else "for example row 0 of what you return now")
        broken.note("row", (
            f"{fn} should return a point of shape ({d},), not (1, {d}): the values are right, "
            f"but drop the extra dimension ({where})."))
        arr = arr[0]
    elif arr.shape != (d,):
        extra = ""
        if arr.ndim == 2 and arr.shape[1] == d and arr.shape[0] > 1:
            extra = (f" That is {arr.shape[0]} points; the curve at one t is a single point "
                     f"with {d} coordinates.")
        elif arr.ndim == 0:
            extra = f" The curve is in {d}-D, so each point has {d} coordinates."
        raise CheckFailure(f"{call} should return one point, an array of shape ({d},); "
                           f"got {describe(got)}.{extra}")
    return arr.astype(float), ""


def judge_point(got: object, expected: np.ndarray, *, fn: str, ctrl: np.ndarray, t: float,
                atol: float, broken: Broken, hint: str = "") -> None:
    """A point within ``atol`` (each coordinate) of ``expected``; raise CheckFailure otherwise."""
    n, d = len(ctrl) - 1, ctrl.shape[1]
    call = call_text(fn, ctrl, t)
    point, where = as_point(got, fn=fn, call=call, n=n, d=d, broken=broken)
    try:
        expect_close(point, expected, rtol=0, atol=atol, name=f"{call}{where}",
                     at=lambda i: f"coordinate {i[0]} of {show_point(expected, DIGITS)}")
    except CheckFailure as off:
        note = weight_sum_note(point, ctrl[0]) if np.all(ctrl == ctrl[0]) else ""
        note = note or reversed_note(point, ctrl, t, atol)
        raise CheckFailure(f"{off}{_endpoint_note(t, ctrl)}{note} {hint}".rstrip()) from None


def _endpoint_note(t: float, ctrl: np.ndarray) -> str:
    if t == 0.0:
        return " A Bezier curve starts at its first control point."
    if t == 1.0:
        return " A Bezier curve ends at its last control point."
    return ""


#: Highest degree at which BPoly (the independent oracle) is used to recognise C(1 - t).
REVERSED_MAX_DEGREE = 40
REVERSED_HINT = (" Your point is C(1 - t): the curve run backwards, from the last control "
                 "point to the first. P_i goes with B_{i,n}(t) = C(n, i) t^i (1 - t)^(n - i), "
                 "and each de Casteljau step is (1 - t) * P_i + t * P_(i+1): the weight t "
                 "belongs to the later point.")


def reversed_note(point: np.ndarray, ctrl: np.ndarray, t: float, atol: float) -> str:
    """The C(1 - t) hint, when the answer measurably is the curve at 1 - t (and not at t)."""
    if len(ctrl) - 1 > REVERSED_MAX_DEGREE or t == 0.5 or np.all(ctrl == ctrl[0]):
        return ""
    backwards = curve_points(ctrl, 1.0 - t)
    if np.all(np.isfinite(backwards)) and float(np.max(np.abs(point - backwards))) <= atol:
        return REVERSED_HINT
    return ""


def weight_sum_note(got: object, point: np.ndarray) -> str:
    """For a polygon of equal points: by what factor the answer scales the point, if it does."""
    try:
        arr = np.asarray(got, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return ""
    if arr.shape != point.shape or not np.all(np.isfinite(arr)):
        return ""
    if np.any(point == 0.0):
        return ""
    ratios = arr / point
    if np.ptp(ratios) < 1e-9 * max(1.0, float(np.max(np.abs(ratios)))) \
            and abs(float(ratios[0]) - 1.0) > 1e-9:
        return f" Your result is {show_number(ratios[0])} times that point: your weights " \
               f"sum to {show_number(ratios[0])}."
    return ""


def judge_endpoint(got: object, ctrl: np.ndarray, t: float, *, fn: str, atol: float,
                   broken: Broken) -> None:
    """At t = 0 (t = 1) the answer must be ctrl[0] (ctrl[-1]) exactly."""
    n, d = len(ctrl) - 1, ctrl.shape[1]
    which, expected = ("first", ctrl[0]) if t == 0.0 else ("last", ctrl[-1])
    call = call_text(fn, ctrl, t)
    point, where = as_point(got, fn=fn, call=call, n=n, d=d, broken=broken)
    if np.array_equal(point, expected):
        return
    err = float(np.max(np.abs(point - expected)))
    message = (f"{fn}(ctrl, {show_number(t)}) must be the {which} control point exactly: "
               f"with ctrl = {show_polygon(ctrl)} expected {show_point(expected)}, got "
               f"{show_point(point)}{where}")
    if err <= atol:
        broken.note("inexact-end", f"{message} (off by {err:.1e}: rounding). "
                                    f"{EXACT_HINTS.get(fn, '')}".rstrip())
        return
    other = ctrl[-1] if t == 0.0 else ctrl[0]
    backwards = (" You returned the other end: your curve runs backwards, C(1 - t)."
                 + REVERSED_HINT.split(":", 1)[1].split(".", 1)[1]
                 if len(ctrl) > 1 and np.array_equal(point, other) else "")
    raise CheckFailure(f"{message}. A Bezier curve starts at its first control point and ends "
                       "at its last one, because there all Bernstein weights but one are 0."
                       + backwards)


def grade_endpoints(student: Student, credit: Credit, fn: str, polygons: Iterable[np.ndarray], *,
                    rtol: float) -> None:
    """Check ``fn`` at t = 0 and t = 1 on every polygon, then award the broken."""
    broken = CONVENTIONS.record()
    for ctrl in polygons:
        for t in (0.0, 1.0):
            got = ask(student, fn, ctrl, t)
            judge_endpoint(got, ctrl, t, fn=fn, atol=rtol * size(ctrl), broken=broken)
    broken.finish(credit)


# ---------------------------------------------------------------------------
# the two control polygons of a split
# ---------------------------------------------------------------------------

def curve_points(ctrl: ArrayLike, s: ArrayLike) -> np.ndarray:
    """Points of the Bezier curve of ``ctrl`` at ``s`` (scalar -> (d,), array -> (m, d))."""
    ctrl = np.asarray(ctrl, dtype=float)
    return BPoly(ctrl[:, None, :], [0.0, 1.0])(s)


def as_polygons(got: object, *, call: str, n: int, d: int) -> tuple[np.ndarray, np.ndarray]:
    """The answer as two float arrays of shape (n + 1, d), or a CheckFailure saying why not."""
    pair = isinstance(got, (list, tuple)) and len(got) == 2
    stacked = isinstance(got, np.ndarray) and got.ndim == 3 and got.shape[0] == 2
    if not (pair or stacked):
        raise CheckFailure(f"{call} should return two control polygons, a tuple (left, right); "
                           f"got {describe(got)}.")
    out: list[np.ndarray] = []
    for side, item in zip(("left", "right"), got):
        name = f"the {side} polygon of {call}"
        arr = expect_array(item, dtype_kind="iuf", name=name)
        if arr.shape != (n + 1, d):
            extra = (f" Each piece is a Bezier curve of the same degree {n}, so it has "
                     f"{n + 1} control points with {d} coordinates each.")
            raise CheckFailure(f"The {side} polygon of {call} should have shape ({n + 1}, {d}); "
                               f"got shape {arr.shape}.{extra}")
        arr = arr.astype(float)
        if not np.all(np.isfinite(arr)):
            raise CheckFailure(f"The {side} polygon of {call} holds values that are not finite.")
        out.append(arr)
    return out[0], out[1]


def judge_split(left: np.ndarray, right: np.ndarray, ctrl: np.ndarray, t: float,
                expected: tuple[np.ndarray, np.ndarray], *, atol: float,
                broken: Broken) -> None:
    """Right polygons pass; swapped or reversed ones are noted; anything else fails."""
    want_left, want_right = expected

    def close(a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.max(np.abs(a - b)) <= atol)

    call = call_text("split_bezier", ctrl, t)
    for swapped in (False, True):
        a, b = (right, left) if swapped else (left, right)
        if not ((close(a, want_left) or close(a[::-1], want_left))
                and (close(b, want_right) or close(b[::-1], want_right))):
            continue
        if swapped:
            broken.note("swapped", (
                f"{call} returned (right, left): return the piece from ctrl[0] to the cut "
                "point first, then the piece from the cut point to ctrl[-1]."))
        backwards = [side for side, got, want in (("left", a, want_left),
                                                  ("right", b, want_right))
                     if not close(got, want)]
        if backwards:
            broken.note("reversed", _reversed_message(backwards, call))
        return
    raise CheckFailure(split_failure(left, right, ctrl, t, expected, call=call, atol=atol))


def _reversed_message(sides: Sequence[str], call: str) -> str:
    which = " and ".join(f"{s} polygon" for s in sides)
    verb = "is" if len(sides) == 1 else "are"
    return (f"The {which} of {call} {verb} reversed: the right control points, listed "
            "backwards. Each piece runs in the direction of the curve: left goes from ctrl[0] "
            "(left[0]) to the cut point C(t) (left[-1]), and right from C(t) (right[0]) to "
            "ctrl[-1] (right[-1]), so that left(s) = C(t s) and right(s) = C(t + (1 - t) s).")


def split_failure(left: np.ndarray, right: np.ndarray, ctrl: np.ndarray, t: float,
                  expected: tuple[np.ndarray, np.ndarray], *, call: str, atol: float) -> str:
    """The first thing wrong with two polygons of the right shape, in the order one checks."""
    def off(a: ArrayLike, b: ArrayLike) -> bool:
        return bool(np.max(np.abs(np.asarray(a) - np.asarray(b))) > atol)

    cut = expected[0][-1]
    if off(left[0], ctrl[0]):
        return (f"{call}: left[0] should be the first control point {show_point(ctrl[0])}, "
                f"since the left piece starts where the curve starts; got "
                f"{show_point(left[0])}. {SPLIT_HINT}")
    if off(right[-1], ctrl[-1]):
        return (f"{call}: right[-1] should be the last control point {show_point(ctrl[-1])}, "
                f"since the right piece ends where the curve ends; got "
                f"{show_point(right[-1])}. {SPLIT_HINT}")
    if off(left[-1], cut) or off(right[0], cut):
        return (f"{call}: left[-1] and right[0] should both be the cut point "
                f"C({show_number(t)}) = {show_point(cut)}, where the two pieces meet; got "
                f"left[-1] = {show_point(left[-1])} and right[0] = {show_point(right[0])}. "
                f"{SPLIT_HINT}")
    samples = np.linspace(0.0, 1.0, 11)
    for side, poly, where in (("left", left, t * samples),
                              ("right", right, t + (1.0 - t) * samples)):
        mine, theirs = curve_points(poly, samples), curve_points(ctrl, where)
        bad = np.flatnonzero(np.max(np.abs(mine - theirs), axis=1) > atol)
        if bad.size:
            k = int(bad[0])
            formula = "t s" if side == "left" else "t + (1 - t) s"
            return (f"{call}: the {side} polygon does not trace its piece of the curve. At "
                    f"s = {show_number(samples[k])} its Bezier curve is at "
                    f"{show_point(mine[k])}, but C({formula}) = C({show_number(where[k], 6)}) = "
                    f"{show_point(theirs[k])}. {SPLIT_HINT}")
    for side, poly, want in (("left", left, expected[0]), ("right", right, expected[1])):
        if off(poly, want):
            row = int(np.argmax(np.max(np.abs(poly - want), axis=1)))
            return (f"{call}: {side}[{row}] should be {show_point(want[row])}; got "
                    f"{show_point(poly[row])}. {SPLIT_HINT}")
    return f"{call} is off by more than {atol:.1e}. {SPLIT_HINT}"


def split_picture(ctrl: np.ndarray, t: float, left: np.ndarray, right: np.ndarray) -> bytes:
    """PNG: the curve, its control polygon, and the student's two polygons (x-y plane)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.5, 4.2))
    ax = fig.add_subplot()
    curve = curve_points(ctrl, np.linspace(0.0, 1.0, 200))
    ax.plot(curve[:, 0], curve[:, 1], color="0.2", lw=2, label="the curve C")
    ax.plot(ctrl[:, 0], ctrl[:, 1], "o--", color="0.6", label="its control polygon")
    s = np.linspace(0.0, 1.0, 100)
    for poly, colour, marker, side in ((left, "tab:blue", "s-", "left"),
                                       (right, "tab:red", "^-", "right")):
        ax.plot(poly[:, 0], poly[:, 1], marker, color=colour, label=f"your {side} polygon")
        piece = curve_points(poly, s)
        ax.plot(piece[:, 0], piece[:, 1], ":", color=colour, lw=1.5,
                label=f"the curve of your {side} polygon")
    cut = curve_points(ctrl, t)
    ax.plot([cut[0]], [cut[1]], "k*", ms=14, label=f"C(t), t = {t:.4g}")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7, loc="best")
    ax.set_title("split_bezier: your two pieces")
    return render_png(fig)


def grade_split(student: Student, ctrl: np.ndarray, t: float,
                expected: tuple[np.ndarray, np.ndarray], *, atol: float, broken: Broken,
                picture: Callable[[str, bytes], None] | None = None) -> None:
    """Call ``split_bezier``, judge the answer, attach a picture when it is not right."""
    n, d = len(ctrl) - 1, ctrl.shape[1]
    got = ask(student, "split_bezier", ctrl, t)
    left, right = as_polygons(got, call=call_text("split_bezier", ctrl, t), n=n, d=d)
    before = len(broken)
    try:
        judge_split(left, right, ctrl, t, expected, atol=atol, broken=broken)
    except CheckFailure:
        if picture is not None and d >= 2:
            picture(f"split at t = {t:.4g}", split_picture(ctrl, t, left, right))
        raise
    if picture is not None and d >= 2 and len(broken) > before:
        picture(f"split at t = {t:.4g}", split_picture(ctrl, t, left, right))
