"""Benchmark cases: ``reference.convex_hull`` and ``reference.delaunay`` against SciPy.

- convex hull (monotone chain) of 1e5 uniform random points in the unit
  square, against ``scipy.spatial.ConvexHull(points).vertices`` (Qhull).
  Target: within 3x of SciPy.
- Delaunay triangulation (Bowyer-Watson, pure Python) of 1e4 uniform random
  points, against ``scipy.spatial.Delaunay`` (Qhull). Target: under 10 s; it is
  not expected to come near Qhull's speed.
- The largest sizes: both hull methods at 1e6 points (Jarvis's march is
  O(nh), a model solution, 20-30x Qhull there), Delaunay at 1e5 points, and
  the exact integer path: the hull of 1e5 int64 points near 2**62 (exact
  integer arithmetic, no float filter) against Qhull on their rounded doubles
  (which is not exact there).

Inputs are made once, from a seeded generator, outside the timed callables.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.spatial as ss

from reference import convex_hull, delaunay

N_HULL = 100_000
N_DELAUNAY = 10_000
N_HULL_LARGEST = 1_000_000
N_DELAUNAY_LARGEST = 100_000
N_HULL_INT64 = 100_000
SEED = 20240614

Case = tuple[str, Callable[[], object], Callable[[], object], str]


def _hull_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    points = np.random.default_rng(SEED).random((N_HULL, 2))
    return (
        lambda: convex_hull(points),
        lambda: ss.ConvexHull(points).vertices,
    )


def _delaunay_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    points = np.random.default_rng(SEED + 1).random((N_DELAUNAY, 2))
    return (
        lambda: delaunay(points),
        lambda: ss.Delaunay(points).simplices,
    )


def _largest_hull_pair(method: str) -> tuple[Callable[[], object], Callable[[], object]]:
    points = np.random.default_rng(SEED + 2).random((N_HULL_LARGEST, 2))
    return (
        lambda: convex_hull(points, method=method),
        lambda: ss.ConvexHull(points).vertices,
    )


def _largest_delaunay_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    points = np.random.default_rng(SEED + 3).random((N_DELAUNAY_LARGEST, 2))
    return (
        lambda: delaunay(points),
        lambda: ss.Delaunay(points).simplices,
    )


def _int64_hull_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    rng = np.random.default_rng(SEED + 4)
    points = rng.integers(0, 2**40, size=(N_HULL_INT64, 2)) + np.int64(2**62)
    rounded = points.astype(np.float64)
    return (
        lambda: convex_hull(points),
        lambda: ss.ConvexHull(rounded).vertices,
    )


def cases() -> list[Case]:
    return [
        ("convex_hull monotone, 1e5 random points", *_hull_pair(), "within 3x"),
        ("delaunay Bowyer-Watson, 1e4 random points", *_delaunay_pair(), "under 10 s"),
        ("convex_hull monotone, 1e6 random points", *_largest_hull_pair("monotone"),
         "within 3x"),
        ("convex_hull jarvis, 1e6 random points", *_largest_hull_pair("jarvis"),
         "O(nh), 20-30x (model solution)"),
        ("delaunay Bowyer-Watson, 1e5 random points", *_largest_delaunay_pair(),
         "~3x at 1e5"),
        ("convex_hull, 1e5 int64 points near 2**62 (exact)", *_int64_hull_pair(),
         "exact; Qhull rounds"),
    ]  # fmt: skip


if __name__ == "__main__":  # one run of these cases: reference_vs_scipy.py --repeat 1
    import sys
    from pathlib import Path

    from reference_vs_scipy import main

    sys.exit(main(["--repeat", "1", *sys.argv[1:]], only=Path(__file__).stem))
