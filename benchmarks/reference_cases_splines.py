"""Benchmark cases: ``reference.CubicSpline`` against SciPy's.

Each case builds a spline on 1e3 knots and evaluates it at 1e6 points; the
target is to be within a factor 2 of :class:`scipy.interpolate.CubicSpline`.
Inputs are made once, from a seeded generator, outside the timed callables.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.interpolate as si

from reference import CubicSpline

N_KNOTS = 1_000
N_EVAL = 1_000_000
TARGET = "within 2x"


def cases() -> list[tuple[str, Callable[[], object], Callable[[], object], str]]:
    rng = np.random.default_rng(20240611)
    x = np.cumsum(rng.uniform(0.5, 1.5, N_KNOTS))
    y = np.sin(x) + 0.1 * rng.normal(size=N_KNOTS)
    y_periodic = y.copy()
    y_periodic[-1] = y_periodic[0]
    y_plane = np.column_stack([np.cos(x), np.sin(x)])
    t_random = rng.uniform(x[0], x[-1], N_EVAL)  # unsorted: one binary search per point
    t_sorted = np.linspace(x[0] - 1.0, x[-1] + 1.0, N_EVAL)  # plotting grid, with extrapolation

    def pair(y_data, bc, t):
        return (
            lambda: CubicSpline(x, y_data, bc_type=bc)(t),
            lambda: si.CubicSpline(x, y_data, bc_type=bc)(t),
        )

    spec = [
        ("natural, random t", y, "natural", t_random),
        ("not-a-knot, random t", y, "not-a-knot", t_random),
        ("periodic, random t", y_periodic, "periodic", t_random),
        ("natural, sorted t", y, "natural", t_sorted),
        ("natural, (n, 2) values, sorted t", y_plane, "natural", t_sorted),
    ]
    return [
        (f"CubicSpline 1e3 knots + 1e6 evals: {label}", *pair(data, bc, t), TARGET)
        for label, data, bc, t in spec
    ]


if __name__ == "__main__":  # one run of these cases: reference_vs_scipy.py --repeat 1
    import sys
    from pathlib import Path

    from reference_vs_scipy import main

    sys.exit(main(["--repeat", "1", *sys.argv[1:]], only=Path(__file__).stem))
