"""What the approximation checks share: the nodes, and how a student's code used `f`.

Released with the public checks (so it uses SciPy, never the `reference`
package, which students do not have); the hidden checks import it too. The
functions the checks pass to student code are wrapped in
:func:`autograder.engine.callbacks.traced`, so after a call the check knows every
point where the student's code evaluated them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.interpolate import BarycentricInterpolator

from autograder.engine.callbacks import Traced, traced
from autograder.checks import CheckFailure, Credit, Student, expect_close, plural, show_number

#: two points count as the same node within this distance (nodes are computed
#: in double precision in different ways: -cos(j pi / n) and sin(...) differ by ~1e-16)
SAME_NODE = 1e-12
_LABEL = {"chebyshev": "Chebyshev", "equispaced": "equispaced"}
#: the point grid of the notebook's `GRID`
GRID = np.linspace(-1.0, 1.0, 1001)
#: the share of a value check kept by an interpolant that is right on its own n + 1
#: nodes when they are not the nodes asked for: the barycentric formula is right,
#: the choice of nodes (the other half of the exercise) is not
WRONG_NODES_CREDIT = 0.5
#: an interpolant on the student's own nodes counts as right within this relative
#: distance: their nodes may be badly conditioned, the formula is still recognisable
OWN_NODES_RTOL = 1e-8
#: part credit on the student's own nodes only where rounding cannot decide it: two right
#: evaluations on nodes with Lebesgue constant L differ by up to about L * 1e-16, so up to
#: L = 1e6 they agree to OWN_NODES_RTOL with a margin of 50. Beyond (equispaced at n = 31
#: has L ~ 1e7, at n = 40 ~ 5e9) whether they match would depend on the data, and a
#: verdict must depend on the code alone
MAX_OWN_LEBESGUE = 1e6
#: the lecture's reason for the sample at a node (its LagrangeInterp1D tests the distance)
NODE_REASON = (
    "at a node t = x_j the barycentric formula divides by t - x_j = 0, so w_j / (t - x_j) is "
    "infinite and the quotient is inf / inf = NaN. As the lecture's LagrangeInterp1D does "
    "(if abs(tdiff) < 1e-15: return fvals[j]), return the sample f_j where t is a node")


def nodes(n: int, kind: str) -> np.ndarray:
    """The n + 1 nodes of ``kind`` ("chebyshev" or "equispaced") on [-1, 1], ascending."""
    j = np.arange(n + 1)
    return -np.cos(j * np.pi / n) if kind == "chebyshev" else -1.0 + 2.0 * j / n


def scipy_interpolant(f: Traced, n: int, kind: str, t: np.ndarray) -> np.ndarray:
    """SciPy's interpolant of ``f`` (called directly, so not recorded) at ``t``."""
    x = nodes(n, kind)
    return np.asarray(BarycentricInterpolator(x, f(x))(t), dtype=float)


def _off(points: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The points that are not within SAME_NODE of any target."""
    if points.size == 0 or targets.size == 0:
        return points
    distance = np.abs(points[:, None] - targets[None, :]).min(axis=1)
    return points[distance > SAME_NODE]


def distinct_points(f: Traced) -> np.ndarray:
    """Where student code evaluated ``f``, ascending, each point once (within SAME_NODE)."""
    points = np.sort(np.asarray(f.points, dtype=float).reshape(-1))
    if points.size == 0:
        return points
    keep = np.concatenate([[True], np.diff(points) > SAME_NODE])
    return points[keep]


def own_nodes(f: Traced, n: int) -> np.ndarray | None:
    """The student's own node set: exactly n + 1 distinct points in [-1, 1], or None."""
    points = distinct_points(f)
    if points.size != n + 1 or not np.all(np.isfinite(points)) \
            or np.any(np.abs(points) > 1.0 + SAME_NODE):
        return None
    return points


def lebesgue_constant(points: np.ndarray) -> float:
    """max over GRID of sum_j |l_j(t)| for the Lagrange basis of ``points`` (depends on the
    points alone, never on f)."""
    basis = BarycentricInterpolator(points, np.eye(points.size))(GRID)
    value = float(np.max(np.sum(np.abs(basis), axis=1)))
    return value if np.isfinite(value) else float("inf")


def _ignores_kind(student: Student, n: int, kind: str) -> bool:
    """Whether the student's interpolation_nodes(n, kind) itself returns the other kind."""
    other = "equispaced" if kind == "chebyshev" else "chebyshev"
    try:
        x = np.asarray(student.interpolation_nodes(n, kind), dtype=float).reshape(-1)
    except Exception:  # noqa: BLE001 - any failure: their nodes are not the other kind
        return False
    return x.shape == (n + 1,) and not _off(x, nodes(n, other)).size


def wrong_node_set(student: Student, f: Traced, n: int, kind: str, *, what: str) -> str:
    """The message for a submission that sampled f once at n + 1 points, the wrong ones."""
    points = distinct_points(f)
    other = "equispaced" if kind == "chebyshev" else "chebyshev"
    if not _off(points, nodes(n, other)).size:
        fix = (f"your interpolation_nodes({n}, {kind!r}) itself returns the {_LABEL[other]} "
               "nodes: make it honour `kind`" if _ignores_kind(student, n, kind)
               else "pass the kind on to interpolation_nodes")
        return (f"{what} evaluated f at the {_LABEL[other]} nodes, but nodes={kind!r} asks for "
                f"the {_LABEL[kind]} nodes: {fix}.")
    wrong = _off(points, nodes(n, kind))
    return (f"{what} sampled f at n + 1 = {n + 1} points, but they are the wrong node set: "
            f"{plural(wrong.size, 'point')} (for example x = {show_number(wrong[0])}) "
            f"{'is' if wrong.size == 1 else 'are'} not among the {_LABEL[kind]} nodes "
            f"x_j = {'-cos(j pi / n)' if kind == 'chebyshev' else '-1 + 2 j / n'}.")


def nan_at_nodes(got: object, t: np.ndarray, n: int, kind: str) -> np.ndarray | None:
    """Where ``got`` is NaN at a point of ``t`` that is a node (None if ``got`` is no array)."""
    try:
        arr = np.asarray(got, dtype=float)
    except (TypeError, ValueError):
        return None
    if arr.shape != np.shape(t):
        return None
    flat = np.ravel(np.asarray(t, dtype=np.float64))
    at_node = np.abs(flat[:, None] - nodes(n, kind)[None, :]).min(axis=1) <= SAME_NODE
    return np.isnan(arr.reshape(-1)) & at_node


def without_nan_at_nodes(got: object, expected: np.ndarray, t: np.ndarray, n: int,
                         kind: str) -> object:
    """``got`` with NaN at the nodes replaced by the expected values there.

    NaN at a node is one mistake, charged once by the check at the nodes
    (``interpolant_at_the_nodes``); the value checks grade the other points.
    """
    mask = nan_at_nodes(got, t, n, kind)
    if mask is None or not mask.any():
        return got
    arr = np.array(got, dtype=float).reshape(-1)
    arr[mask] = np.asarray(expected, dtype=float).reshape(-1)[mask]
    return arr.reshape(np.shape(t))


def expect_values(student: Student, f: Traced, got: object, expected: np.ndarray, *,
                  n: int, kind: str, t: np.ndarray, atol: float, rtol: float = 0.0,
                  credit: Credit, name: str) -> None:
    """Values at ``t`` right, or right on the student's own (wrong) nodes for part credit.

    NaN at a node is not charged here (see :func:`without_nan_at_nodes`). A
    student who sampled f once at n + 1 points that are not the nodes asked
    for, and whose values are the interpolant on those points, keeps
    WRONG_NODES_CREDIT of the check, with a message naming the node set.
    """
    got = without_nan_at_nodes(got, expected, t, n, kind)
    try:
        expect_close(got, expected, rtol=rtol, atol=atol, name=name)
        return
    except CheckFailure:
        own = own_nodes(f, n)
        if own is None or not _off(own, nodes(n, kind)).size \
                or lebesgue_constant(own) > MAX_OWN_LEBESGUE:
            raise
        mine = np.asarray(BarycentricInterpolator(own, f(own))(t), dtype=float)
        try:
            expect_close(got, mine, rtol=OWN_NODES_RTOL,
                         atol=OWN_NODES_RTOL * (float(np.max(np.abs(mine))) or 1.0), name=name)
        except CheckFailure:
            pass
        else:
            credit.partial(WRONG_NODES_CREDIT, wrong_node_set(student, f, n, kind, what=name)
                           + " Your values are right for your own nodes, so this check keeps "
                           f"{WRONG_NODES_CREDIT:.0%} of its points.")
        raise


def expect_sampled_at_nodes(student: Student, f: Traced, n: int, kind: str, *,
                            what: str) -> None:
    """Fail unless ``f`` was evaluated at each of the n + 1 nodes of ``kind`` and nowhere else.

    The message names what was observed: the wrong node set (and whether it is
    the other kind, and whose mistake that is), points off the nodes, or a node
    missed. Evaluating the nodes more than once is charged once per submission,
    by the hidden check ``evaluates_f_once_per_node`` (see :func:`cost_share`).
    """
    x, points = nodes(n, kind), f.points
    off = _off(points, x)
    if off.size and own_nodes(f, n) is not None:
        raise CheckFailure(wrong_node_set(student, f, n, kind, what=what))
    if off.size:
        raise CheckFailure(
            f"{what} evaluated f at {plural(off.size, 'point')} that are not among the "
            f"n + 1 = {n + 1} {_LABEL[kind]} nodes (for example at x = {show_number(off[0])}). "
            "An interpolant may use f only at its nodes: sample f(x) once at the nodes "
            "and compute everything else from those values.")
    missing = _off(x, points)
    if missing.size:
        raise CheckFailure(
            f"{what} never evaluated f at {plural(missing.size, 'node')} (for example "
            f"x = {show_number(missing[0])}): sample f at all n + 1 nodes during the call, "
            "before returning (f cannot be called once the call has returned).")


def cost_share(uses: list[tuple[str, Traced, int]], credit: Credit) -> None:
    """Charge extra evaluations of f once, in proportion: the mean of needed / used per call.

    ``uses`` lists (what was called, its traced f, how many evaluations it needs).
    One redundant f(x) in one of three calls keeps 5/6 of this one check.
    """
    shares, notes = [], []
    for what, f, needed in uses:
        shares.append(min(1.0, needed / f.evaluations) if f.evaluations else 1.0)
        if f.evaluations > needed:
            notes.append(f"{what} evaluated f at {f.evaluations} points in "
                         f"{plural(f.calls, 'call')}, but {needed} evaluations are enough")
    if notes:
        credit.partial(float(np.mean(shares)), "; ".join(notes) + (
            ". The values are right, but sample f once, at all nodes together (f(x) with the "
            "array of nodes), and reuse the samples."))


def nan_from_nodes(student: Student, function: Callable[..., np.ndarray], ns: Sequence[int],
                   errors: np.ndarray) -> np.ndarray:
    """``errors`` of convergence with each NaN that comes from p being NaN at the nodes of GRID
    replaced by what the student's own p gives at the other points of GRID.

    NaN at a node is charged once, by the check at the nodes; convergence is
    then graded on the rest of its work (its own p elsewhere must still be right).
    """
    out = np.array(errors, dtype=float)
    for k in np.flatnonzero(np.isnan(out)):
        try:
            values = np.asarray(student.make_interpolant(traced(function), ns[k])(GRID),
                                dtype=float)
        except Exception:  # noqa: BLE001 - a failing probe leaves the NaN to be reported
            continue
        mask = nan_at_nodes(values, GRID, ns[k], "chebyshev")
        if mask is None or not mask.any() or np.isnan(values[~mask]).any():
            continue
        out[k] = np.max(np.abs(values[~mask] - function(GRID[~mask])))
    return out
