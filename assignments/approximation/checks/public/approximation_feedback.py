"""What the approximation checks share: the nodes, and how a student's code used `f`.

Released with the public checks (so it uses SciPy, never the `reference`
package, which students do not have); the hidden checks import it too. The
functions the checks pass to student code are wrapped in
:func:`autograder.engine.callbacks.traced`, so after a call the check knows every
point where the student's code evaluated them.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BarycentricInterpolator

from autograder.engine.callbacks import Traced
from autograder.checks import CheckFailure, Credit, plural, show_number

#: two points count as the same node within this distance (nodes are computed
#: in double precision in different ways: -cos(j pi / n) and sin(...) differ by ~1e-16)
SAME_NODE = 1e-12
_LABEL = {"chebyshev": "Chebyshev", "equispaced": "equispaced"}
#: the point grid of the notebook's `GRID`
GRID = np.linspace(-1.0, 1.0, 1001)


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


def expect_sampled_at_nodes(f: Traced, n: int, kind: str, credit: Credit, *, what: str) -> None:
    """Fail unless ``f`` was evaluated exactly once at each of the n + 1 nodes of ``kind``.

    The message names what was observed: points off the nodes (and whether they
    are the other kind of nodes), a node missed, or nodes evaluated more than once
    (half credit: the values are right, the cost is not).
    """
    x, points = nodes(n, kind), f.points
    off = _off(points, x)
    other = "equispaced" if kind == "chebyshev" else "chebyshev"
    if off.size and not _off(points, nodes(n, other)).size:
        raise CheckFailure(
            f"{what} evaluated f at the {_LABEL[other]} nodes, but nodes={kind!r} asks for "
            f"the {_LABEL[kind]} nodes: pass the kind on to interpolation_nodes.")
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
    if f.evaluations > n + 1:
        credit.partial(0.5, (
            f"{what} evaluated f at {f.evaluations} points in {plural(f.calls, 'call')}, but "
            f"n + 1 = {n + 1} evaluations are enough: the values are right, but sample f once, "
            "at all nodes together (f(x) with the array of nodes), and reuse the samples."))
