"""Staged feedback on nodes, weights, interpolants and the Runge plot.

Shared by the public and the hidden checks. Every ``judge_*`` function takes
what the student returned and what was expected (computed by the caller), and
either returns (right), ends the check with ``credit.partial`` (right maths,
broken convention), or raises ``CheckFailure`` with a message that says what
is wrong, where, and how to fix it. Order of the stages: type, shape, finite
values, known conventions, values, and where the first bad value is.

Nothing here computes an interpolant: the caller passes the expected values,
so this module gives away no solution.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from autograder.checks import (
    CheckFailure,
    Conventions,
    Credit,
    Feedback,
    FigureData,
    Student,
    call_for_figure,
    curve_pieces,
    describe,
    expect_array,
    expect_close,
    expect_figure,
    expect_number,
    explain_errors,
    sentences,
    show_number,
)

# ---------------------------------------------------------------------------
# tolerances, each with its reason
# ---------------------------------------------------------------------------

#: Nodes. Every correct formula (``np.linspace``, ``-1 + 2 j / n``,
#: ``2 (j / n - 1/2)``, ``-cos(j pi / n)``, ``sin((2 j - n) pi / (2 n))``)
#: lands within a few ulps of the reference: at most about 4e-16 apart on
#: [-1, 1]. Any wrong formula is off by far more: the closest two Chebyshev
#: nodes of degree 1000 are still 4.9e-6 apart.
NODE_ATOL = 1e-14

#: Weights, relative to the largest one. Exact integers give correctly rounded
#: ratios (error 1e-16); the log-gamma route loses more: ``lgamma(1101)`` is
#: about 6.6e3, so its rounding error (about 1e-12) becomes a relative error
#: of that size after ``exp``. 1e-9 accepts both; a wrong formula is off by O(1).
WEIGHT_RTOL = 1e-9
#: Ratios below the normal range of doubles (2.2e-308) cannot be stored
#: accurately: any value under this bound, 0 included, is accepted there.
WEIGHT_ATOL = 1e-300

#: Curves in a plot: largest error relative to max(1, max |curve|). Any
#: double-precision evaluation is within 1e-12; a wrong degree or node family
#: is off by more than 1e-2.
CURVE_RTOL = 1e-6
#: A drawn line counts as a curve from this many finite points at distinct x on:
#: node markers (n + 1 points) are not curves, and neither is a line through the
#: nodes repeated (every interpolant equals f there, so it would match them all).
MIN_CURVE_POINTS = 50
#: A curve must reach this close to both ends of [-1, 1].
CURVE_REACH = 0.95

#: Share of a check's points kept when the maths is right but a convention is not.
CONVENTIONS = Conventions({
    "descending": 0.5,       # the right nodes, listed from +1 down to -1
    "first-form": 0.5,       # the first barycentric form: values scaled by the weights' scale
    "array-for-scalar": 0.5,  # an array of one value for a scalar t
    "no-return": 0.5,         # plot_runge drew a figure but did not return it
})


#: How to keep equispaced weights finite (shown when they overflow or underflow).
EQUISPACED_HINT = (
    "The binomials C(n, j) grow like 2^n: C(1100, 550) is about 3.3e329, beyond the largest "
    "double (1.8e308), and factorials overflow much sooner (171! > 1.8e308). Only the ratios "
    "of the weights matter: divide every C(n, j) by the largest, C(n, n // 2), before "
    "converting to float (Python's exact integers divide correctly rounded), or work with "
    "logarithms (math.lgamma) and subtract the largest before exp.")
#: The same for Chebyshev weights, which never need large numbers.
CHEBYSHEV_HINT = ("Chebyshev weights need no large numbers: w_j = (-1)^j, halved for j = 0 "
                  "and j = n.")

#: Known wrong answers, named (public and hidden checks compare with them).
FIRST_KIND = ("these are Chebyshev points of the first kind (the roots of T_{n+1}), which "
              "stop short of -1 and 1; the assignment asks for the second kind, "
              "x_j = -cos(j pi / n), j = 0, ..., n.")
NOT_HALVED = ("the end weights must be halved: w_j = (-1)^j for 0 < j < n, and "
              "w_0 = 1/2, w_n = (-1)^n / 2.")
CHEBYSHEV_FOR_EQUISPACED = ("these are Chebyshev weights (alternating +-1); equispaced nodes "
                            "need w_j = (-1)^j C(n, j).")


def alternating(n: int) -> np.ndarray:
    """``(-1)^j`` for j = 0, ..., n: Chebyshev weights that forgot to halve the ends."""
    return np.where(np.arange(n + 1) % 2 == 0, 1.0, -1.0)


def runge(x: ArrayLike) -> np.ndarray:
    """Runge's function of the notebook, 1 / (1 + 16 x^2)."""
    return 1.0 / (1.0 + 16.0 * np.asarray(x, dtype=float) ** 2)


def not_runge(x: ArrayLike, rng: np.random.Generator) -> np.ndarray:
    """Smooth data at ``x`` that are not Runge's function (a new phase per submission).

    Checks that ask for the data back at the nodes use these, so that a
    ``lagrange_interp`` that ignores ``fvals`` and returns the lecture's
    1 / (1 + 16 x^2) fails them.
    """
    x = np.asarray(x, dtype=float)
    return np.cos(3.0 * x + rng.uniform(0.5, 1.5)) + 0.5 * x


# ---------------------------------------------------------------------------
# calling the student
# ---------------------------------------------------------------------------


def call_weights(fn: Callable[[int], object], n: int, *, call: str, hint: str) -> object:
    """``fn(n)``, turning an ``OverflowError`` raised inside it into a readable failure."""
    with explain_errors(call, {"OverflowError": f"Your weights overflow for n = {n}. {hint}"}):
        return fn(n)


# ---------------------------------------------------------------------------
# nodes
# ---------------------------------------------------------------------------


def _close(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= atol))


def judge_nodes(got: object, expected: np.ndarray, *, call: str, what: str, credit: Credit,
                known: Mapping[str, np.ndarray] | None = None) -> None:
    """Nodes: n + 1 of them, finite, ascending, equal to ``expected`` within ``NODE_ATOL``.

    ``what`` names the family ("equispaced nodes", "Chebyshev nodes"). ``known``
    maps a message to a known wrong answer (e.g. points of the first kind).
    """
    expected = np.asarray(expected, dtype=float)
    m = expected.size
    arr = expect_array(got, dtype_kind="iuf", name=call)
    if arr.ndim != 1:
        raise CheckFailure(f"{call} should be a 1-D array of n + 1 = {m} nodes; got "
                           f"{describe(got)}.")
    if arr.size != m:
        hint = (" Did you stop at j = n - 1? j runs over 0, 1, ..., n." if arr.size == m - 1
                else "")
        raise CheckFailure(f"{call} returned {arr.size} nodes; degree n = {m - 1} needs "
                           f"n + 1 = {m} nodes.{hint}")
    arr = arr.astype(float)
    try:
        expect_close(arr, expected, rtol=0, atol=NODE_ATOL, name=call,
                     at=lambda i: f"node {i[0]}", hint=_node_hints(arr, expected))
    except CheckFailure:
        if m > 1 and _close(arr, expected[::-1], NODE_ATOL):
            fix = " (x_j = -cos(j pi / n) rises from -1 to 1; cos(j pi / n) falls)" \
                if "Chebyshev" in what else ""
            CONVENTIONS.partial(credit, "descending",
                                f"{call}: your {what} are in descending order; the assignment "
                                f"asks for ascending{fix}.")
        for message, wrong in (known or {}).items():
            if _close(arr, np.asarray(wrong, dtype=float), NODE_ATOL):
                raise CheckFailure(f"{call}: {message}") from None
        raise


def _node_hints(arr: np.ndarray, expected: np.ndarray) -> str:
    """What is wrong with the nodes as a whole: their range, their order."""
    parts: list[str] = []
    if abs(arr[0] - expected[0]) > NODE_ATOL or abs(arr[-1] - expected[-1]) > NODE_ATOL:
        parts.append(f"the nodes should run from {show_number(expected[0])} to "
                     f"{show_number(expected[-1])}; yours run from {show_number(arr[0])} to "
                     f"{show_number(arr[-1])}")
    steps = np.flatnonzero(np.diff(arr) <= 0)
    if steps.size:
        j = int(steps[0])
        parts.append(f"the nodes must be ascending, but node {j + 1} ({show_number(arr[j + 1])}) "
                     f"is not larger than node {j} ({show_number(arr[j])})")
    return sentences(parts)


# ---------------------------------------------------------------------------
# weights
# ---------------------------------------------------------------------------


def judge_weights(got: object, expected: np.ndarray, *, call: str, n: int, hint: str = "",
                  known: Mapping[str, np.ndarray] | None = None) -> None:
    """Weights at any common scale: ``got / got[k]`` against ``expected / expected[k]``.

    ``k`` is the index of the largest expected weight (it never underflows).
    ``hint`` explains how to avoid overflow for this family; ``known`` maps a
    message to a known wrong answer (compared at any scale).
    """
    expected = np.asarray(expected, dtype=float)
    m = expected.size
    arr = expect_array(got, dtype_kind="iuf", name=call)
    if arr.ndim != 1 or arr.size != m:
        raise CheckFailure(f"{call} should be a 1-D array of n + 1 = {m} weights, one per "
                           f"node; got {describe(got)}.")
    arr = arr.astype(float)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        j = int(bad[0])
        raise CheckFailure(f"{call}: weight {j} is {arr[j]}: your weights overflow for "
                           f"n = {n} ({bad.size} of {m} weights are not finite). {hint}")
    k = int(np.argmax(np.abs(expected)))
    if arr[k] == 0:
        every = "every weight is 0" if not arr.any() else f"weight {k} is 0"
        raise CheckFailure(f"{call}: your weights for n = {n} underflow to zero: {every}, "
                           f"but weight {k} is the largest in exact arithmetic. Scale the "
                           f"weights so that the largest is about 1. {hint}")
    ratio, want = arr / arr[k], expected / expected[k]
    under = np.flatnonzero((ratio == 0) & (np.abs(want) > WEIGHT_ATOL))
    zero = (f"Weight {under[0]} is 0: it underflowed although its true size, "
            f"{want[under[0]]:.3g} times the largest, is a normal double." if under.size else "")
    try:
        expect_close(ratio, want, rtol=WEIGHT_RTOL, atol=WEIGHT_ATOL,
                     name=f"{call} divided by weight {k} (the largest)",
                     at=lambda i: f"weight {i[0]}",
                     hint=sentences(["only ratios matter (any common scale is fine)", zero]))
    except CheckFailure:
        for message, wrong in (known or {}).items():
            wrong = np.asarray(wrong, dtype=float)
            if np.allclose(ratio, wrong / wrong[k], rtol=WEIGHT_RTOL, atol=WEIGHT_ATOL):
                raise CheckFailure(f"{call}: {message}") from None
        flipped = np.flatnonzero((ratio != 0) & (np.abs(want) > WEIGHT_ATOL)
                                 & (np.sign(ratio) != np.sign(want)))
        if flipped.size:
            raise CheckFailure(f"{call}: weight {flipped[0]} has the wrong sign: the weights "
                               f"alternate in sign, w_j = (-1)^j |w_j| (a common factor, even "
                               f"-1, is fine); {flipped.size} of {m} weights have the wrong "
                               "sign.") from None
        raise


# ---------------------------------------------------------------------------
# interpolant values
# ---------------------------------------------------------------------------


def _where(t: float, nodes: np.ndarray) -> str:
    """Where ``t`` lies relative to the nodes: on one, next to one, or between."""
    j = int(np.argmin(np.abs(nodes - t)))
    if t == nodes[j]:
        return f"t = {show_number(t)}, which is node x_{j}"
    gap = abs(t - nodes[j])
    if gap <= 4 * np.spacing(max(abs(nodes[j]), abs(t))) or gap < 1e-300:
        return f"t = {show_number(t)}, right next to node x_{j} = {show_number(nodes[j])}"
    return f"t = {show_number(t)}"


def scale_factor(got: np.ndarray, expected: np.ndarray, off_node: np.ndarray,
                 rtol: float = 1e-6) -> float | None:
    """``c`` if ``got == c * expected`` wherever ``off_node`` (``c != 1``), else None.

    Points on a node are left out: there a first-form program that tests for
    nodes returns the data itself, unscaled.
    """
    got, expected = got[off_node], expected[off_node]
    big = np.abs(expected) > 1e-3 * np.max(np.abs(expected), initial=0.0)
    if big.sum() < 2 or not np.all(np.isfinite(got)):
        return None
    ratios = got[big] / expected[big]
    c = float(np.median(ratios))
    if c == 0 or abs(c - 1) < 1e-6:
        return None
    if np.allclose(got, c * expected, rtol=rtol, atol=rtol * abs(c) * np.max(np.abs(expected))):
        return c
    return None


def judge_values(got: object, expected: ArrayLike, *, t: ArrayLike, nodes: np.ndarray,
                 tol: float, call: str, credit: Credit) -> None:
    """Values of the interpolant at ``t``: same shape, no NaN, within ``tol`` (absolute)."""
    expected = np.asarray(expected, dtype=float)
    t = np.asarray(t, dtype=float)
    scalar = isinstance(got, (int, float, np.number)) or (isinstance(got, np.ndarray)
                                                          and got.ndim == 0)
    if expected.ndim and scalar:
        raise CheckFailure(f"{call} returned one number for an array t of shape {t.shape}; "
                           "it should return one value per entry of t, in an array of the same "
                           "shape (loop over t, or better, compute with whole arrays).")
    arr = expect_array(got, dtype_kind="iuf", name=call)
    if arr.shape != expected.shape:
        raise CheckFailure(f"{call}: t has shape {t.shape}, so the result should too; got "
                           f"shape {arr.shape}.")
    arr = arr.astype(float)
    flat, want, tt = arr.ravel(), expected.ravel(), t.ravel()
    bad = np.flatnonzero(~np.isfinite(flat))
    if bad.size:
        i = int(bad[0])
        raise CheckFailure(f"{call} returned {flat[i]} at {_where(tt[i], nodes)} (entry {i}); "
                           f"expected {want[i]:.15g}. {bad.size} of {flat.size} values are not "
                           "finite." + _nan_hint(tt[i], nodes))
    try:
        expect_close(flat, want, rtol=0, atol=tol, name=call,
                     at=lambda i: f"{_where(tt[i[0]], nodes)} (entry {i[0]})")
    except CheckFailure:
        c = scale_factor(flat, want, ~np.isin(tt, nodes))
        if c is not None:
            CONVENTIONS.partial(credit, "first-form",
                                f"{call}: every value is {show_number(c, 6)} times the interpolant. That is "
                                "what the first barycentric form l(t) sum_j w_j f_j / (t - x_j) "
                                "gives when the weights come at another scale. The weights may "
                                "have any common scale: divide by sum_j w_j / (t - x_j) (the "
                                "second form), and the scale cancels.")
        raise


def _nan_hint(t: float, nodes: np.ndarray) -> str:
    j = int(np.argmin(np.abs(nodes - t)))
    if t == nodes[j]:
        return (f" At a node, w_j / (t - x_j) is w_j / 0: return fvals[{j}] when "
                f"t == xnodes[{j}] (exactly, no tolerance).")
    return (f" t is {abs(t - nodes[j]):.3g} from node x_{j}: w_{j} / (t - x_{j}) can overflow to "
            "inf there, and inf / inf is nan. Multiply every term by the distance to the "
            "nearest node (it cancels in the quotient) so that no term overflows.")


def judge_exact(got: object, fvals: np.ndarray, nodes: np.ndarray, index: np.ndarray, *,
                call: str) -> None:
    """At ``t = nodes[index]`` the answer must be ``fvals[index]``, bit for bit."""
    index = np.asarray(index)
    arr = expect_array(got, dtype_kind="iuf", name=call)
    if arr.shape != index.shape:
        raise CheckFailure(f"{call}: t has shape {index.shape}, so the result should too; "
                           f"got shape {arr.shape}.")
    arr = arr.astype(float).ravel()
    for i, j in enumerate(index.ravel()):
        j = int(j)
        if not arr[i] == fvals[j]:  # also catches nan
            raise CheckFailure(
                f"lagrange_interp returned {show_number(arr[i])} at node x_{j} = "
                f"{show_number(nodes[j])}; it must return fvals[{j}] = {show_number(fvals[j])} "
                "exactly. Compare t == xnodes[j] "
                "exactly (not with a tolerance) and return fvals[j] there.")


def judge_scalar(got: object, *, call: str, credit: Credit) -> float:
    """A scalar ``t`` gives a scalar: a float, or a 0-d array. Returns the value."""
    try:
        arr = np.asarray(got) if isinstance(got, (list, tuple, np.ndarray)) else None
    except ValueError:  # ragged
        arr = None
    if arr is not None and arr.ndim and arr.size == 1 and arr.dtype.kind in "iuf":
        CONVENTIONS.partial(credit, "array-for-scalar",
                            f"{call} returned {describe(got)} for a scalar t; return a scalar "
                            "(a float) when t is a scalar, e.g. with float(...) or result[()] "
                            "on a 0-d array.")
    return expect_number(got, name=call, hint="A scalar t gives one number.")


# ---------------------------------------------------------------------------
# the Runge plot
# ---------------------------------------------------------------------------


class Curve(NamedTuple):
    """A reference curve to look for in a plot: its name and a function of x."""

    name: str
    fn: Callable[[np.ndarray], np.ndarray]


def draw_runge_plot(student: Student, feedback: Feedback, n: int) -> tuple[FigureData, str, str]:
    """Call ``plot_runge(n)``; return (figure data, note, call text), the picture attached.

    The note is "" when the figure was returned, and says so when it was only drawn.
    """
    call = f"plot_runge({n})"
    value, figure = call_for_figure(student, "plot_runge", n, feedback=feedback)
    if figure is None:
        figure = expect_figure(value, name=call, hint="no figure was drawn either")
    if figure is value:
        return figure, "", call
    return figure, (f"{call} returned {describe(value)}, not the Figure; it drew one, so I "
                    "graded that, but end plot_runge with `return fig`."), call


def grade_runge_plot(student: Student, feedback: Feedback, credit: Credit, n: int,
                     interpolant: Callable[[str, int], Callable[[np.ndarray], ArrayLike]]) -> None:
    """Call ``plot_runge(n)`` and find Runge's function and its two interpolants of degree n.

    ``interpolant(family, m)`` is the interpolant of degree ``m`` in the
    ``"equispaced"`` or ``"Chebyshev"`` nodes; those of degree n - 1 and n + 1
    only sharpen the message (a common off-by-one).
    """
    figure, note, call = draw_runge_plot(student, feedback, n)
    families = ("equispaced", "Chebyshev")
    wanted = [Curve("Runge's function 1/(1 + 16x^2)", runge)]
    wanted += [Curve(f"the {family} interpolant", interpolant(family, n)) for family in families]
    nearby = {f"the {family} interpolant": [
        Curve(f"the {family} interpolant of degree {m} ({m + 1} nodes), but {call} asks for "
              f"degree {n} ({n + 1} nodes)", interpolant(family, m)) for m in (n - 1, n + 1)]
        for family in families}
    judge_runge_plot(figure, call=call, wanted=wanted, nearby=nearby, credit=credit, note=note)


def drawn_curves(figure: FigureData) -> list[tuple[np.ndarray, np.ndarray]]:
    """(x, y) of every line or point set with ``MIN_CURVE_POINTS`` finite points at distinct x."""
    return [(xy[:, 0], xy[:, 1]) for xy in curve_pieces(figure)
            if np.unique(xy[:, 0]).size >= MIN_CURVE_POINTS]


def curve_error(curve: tuple[np.ndarray, np.ndarray],
                fn: Callable[[np.ndarray], ArrayLike]) -> tuple[float, float]:
    """Largest error of a drawn curve against ``fn``, relative to max(1, max |fn|); and where."""
    x, y = curve
    want = np.asarray(fn(x), dtype=float)
    err = np.abs(y - want) / max(1.0, float(np.max(np.abs(want))))
    err[~np.isfinite(err)] = np.inf
    i = int(np.argmax(err))
    return float(err[i]), float(x[i])


def _count(k: int) -> str:
    return f"your {k} curve" + ("" if k == 1 else "s")


def judge_runge_plot(figure: FigureData, *, call: str, wanted: Sequence[Curve],
                     nearby: Mapping[str, Sequence[Curve]] | None = None, credit: Credit,
                     note: str = "") -> None:
    """Find each wanted curve among the drawn ones (by values, not labels or colours).

    Each wanted curve is worth an equal share; one that does not reach both
    ends of [-1, 1] gets half its share. ``nearby`` maps a wanted curve's name
    to curves that a common mistake draws instead (other degrees); they only
    sharpen the message.
    """
    curves = drawn_curves(figure)
    share, score = 1.0 / len(wanted), 0.0
    parts: list[str] = []
    found: list[str] = []
    for curve in wanted:
        errors = [curve_error(c, curve.fn) for c in curves]
        best = int(np.argmin([e for e, _ in errors])) if errors else -1
        if best >= 0 and errors[best][0] <= CURVE_RTOL:
            x = curves[best][0]
            found.append(curve.name)
            if x.min() <= -CURVE_REACH and x.max() >= CURVE_REACH:
                score += share
            else:
                score += share / 2
                parts.append(f"{curve.name} in your plot covers only [{show_number(x.min(), 3)}, "
                             f"{show_number(x.max(), 3)}]; draw it over the whole interval [-1, 1]")
            continue
        parts.append(_missing(curve, curves, errors, best, (nearby or {}).get(curve.name, ())))
    if note:
        score *= CONVENTIONS.fractions["no-return"]
        parts.append(note)
    if score >= 1.0 - 1e-12:
        return
    if found and len(found) < len(wanted):
        parts.insert(0, "I found " + " and ".join(found))
    message = sentences(parts)
    if score <= 0.0:
        raise CheckFailure(message)
    credit.partial(score, message)


def _missing(curve: Curve, curves: list[tuple[np.ndarray, np.ndarray]],
             errors: list[tuple[float, float]], best: int, nearby: Sequence[Curve]) -> str:
    if not curves:
        return (f"I could not find {curve.name}: your figure has no curve (a line through at "
                f"least {MIN_CURVE_POINTS} points)")
    text = f"I could not find {curve.name} among {_count(len(curves))}"
    for other in nearby:
        if any(curve_error(c, other.fn)[0] <= CURVE_RTOL for c in curves):
            return text + f"; one of your curves is {other.name}"
    err, x = errors[best]
    return text + f" (the closest one is off by {err:.2g} at x = {show_number(x, 3)})"
