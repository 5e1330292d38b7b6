"""Benchmark cases: ``reference.barycentric_interpolate`` and ``reference.bezier`` against SciPy.

- barycentric interpolation, 100 Chebyshev points, 1e6 evaluation points, against
  :func:`scipy.interpolate.barycentric_interpolate`; both compute their weights
  inside the timed call. Target: no slower than SciPy. SciPy forms the whole
  (1e6, 100) matrix (0.8 GB, more with temporaries); ours works in chunks, so
  :func:`memory_peaks` also reports both peaks, measured with :mod:`tracemalloc`
  (numpy reports its buffers to it).
- a degree-5 Bezier curve in the plane at 1e6 parameter values, against
  :class:`scipy.interpolate.BPoly` built on the single interval ``[0, 1]``
  (construction inside the timed call too). Target: no slower than SciPy.

Inputs are made once, from a seeded generator, outside the timed callables.
"""

from __future__ import annotations

import tracemalloc
from typing import Callable

import numpy as np
import scipy.interpolate as si

from reference import barycentric_interpolate, bezier, chebyshev_nodes

N_NODES = 100
N_EVAL = 1_000_000
N_EXTRAPOLATE = 10_000
BEZIER_DEGREE = 5
SEED = 20240612
TARGET = "no slower than SciPy"

Case = tuple[str, Callable[[], object], Callable[[], object], str]


def _barycentric_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    rng = np.random.default_rng(SEED)
    x = chebyshev_nodes(N_NODES - 1)
    y = np.exp(x) * np.cos(8 * x) + 0.01 * rng.normal(size=N_NODES)
    t = rng.uniform(-1.0, 1.0, N_EVAL)
    return (
        lambda: barycentric_interpolate(x, y, t),
        lambda: si.barycentric_interpolate(x, y, t),
    )


def _bezier_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    rng = np.random.default_rng(SEED + 1)
    ctrl = rng.normal(size=(BEZIER_DEGREE + 1, 2))
    t = rng.uniform(0.0, 1.0, N_EVAL)
    return (
        lambda: bezier(ctrl, t),
        lambda: si.BPoly(ctrl[:, None, :], [0.0, 1.0])(t),
    )


def _extrapolation_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    """1e4 points outside the nodes (first form + Newton form, both scaled)."""
    rng = np.random.default_rng(SEED + 2)
    x = chebyshev_nodes(N_NODES - 1)
    y = np.exp(x) * np.cos(8 * x)
    t = rng.uniform(1.0, 3.0, N_EXTRAPOLATE) * rng.choice([-1.0, 1.0], N_EXTRAPOLATE)
    return (
        lambda: barycentric_interpolate(x, y, t),
        lambda: si.barycentric_interpolate(x, y, t),
    )


def cases() -> list[Case]:
    return [
        ("barycentric 100 Chebyshev nodes, 1e6 points", *_barycentric_pair(), TARGET),
        ("barycentric 100 nodes, 1e4 points outside (extrapolation)", *_extrapolation_pair(),
         "finite, accurate; cost stated"),
        ("bezier degree 5 in 2-D, 1e6 points (vs BPoly)", *_bezier_pair(), TARGET),
    ]


def _peak_bytes(fn: Callable[[], object]) -> int:
    """Peak traced allocation during ``fn()`` (its result included), in bytes."""
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def memory_peaks() -> list[tuple[str, int, int]]:
    ours, theirs = _barycentric_pair()
    return [
        ("barycentric 100 Chebyshev nodes, 1e6 points", _peak_bytes(ours), _peak_bytes(theirs))
    ]


if __name__ == "__main__":  # one run of these cases: reference_vs_scipy.py --repeat 1
    import sys
    from pathlib import Path

    from reference_vs_scipy import main

    sys.exit(main(["--repeat", "1", *sys.argv[1:]], only=Path(__file__).stem))
