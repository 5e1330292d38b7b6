"""Benchmark cases: ``reference.convex_hull`` and ``reference.delaunay`` against SciPy.

- convex hull (monotone chain) of 1e5 uniform random points in the unit
  square, against ``scipy.spatial.ConvexHull(points).vertices`` (Qhull).
  Target: within 3x of SciPy.
- Delaunay triangulation (Bowyer-Watson, pure Python) of 1e4 uniform random
  points, against ``scipy.spatial.Delaunay`` (Qhull). Target: under 10 s; it is
  not expected to come near Qhull's speed.

Inputs are made once, from a seeded generator, outside the timed callables.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.spatial as ss

from reference import delaunay
from reference import convex_hull

N_HULL = 100_000
N_DELAUNAY = 10_000
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


def cases() -> list[Case]:
    return [
        ("convex_hull monotone, 1e5 random points", *_hull_pair(), "within 3x"),
        ("delaunay Bowyer-Watson, 1e4 random points", *_delaunay_pair(), "under 10 s"),
    ]


if __name__ == "__main__":
    import time

    for name, ours_fn, theirs_fn, target in cases():
        timings = []
        for fn in (ours_fn, theirs_fn):
            start = time.perf_counter()
            fn()
            timings.append(time.perf_counter() - start)
        print(f"{name:<48} ours {timings[0]:.3f} s  scipy {timings[1]:.3f} s  ({target})")
