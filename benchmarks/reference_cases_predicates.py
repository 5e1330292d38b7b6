"""Benchmark cases: the exact vectorised predicates against the plain formula.

SciPy has no orientation or in-circle predicate; the peer is the naive
floating-point determinant in NumPy (what a student would write), which is
fast and sometimes wrong. The ratio is the price of exactness.

- ``orient2d_many`` on 1e6 random triples (the filter decides every row);
- ``incircle_many`` on 1e6 random quadruples, corners counter-clockwise;
- ``orient2d_many`` on 1e5 int64 triples near 2**62 (exact integer
  arithmetic on every row; the naive formula on rounded doubles is wrong
  there).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from reference import incircle_many, orient2d_many

N = 1_000_000
N_INT64 = 100_000
SEED = 20240615

Case = tuple[str, Callable[[], object], Callable[[], object], str]


def _naive_orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    det = (p[:, 0] - r[:, 0]) * (q[:, 1] - r[:, 1]) - (p[:, 1] - r[:, 1]) * (q[:, 0] - r[:, 0])
    return np.sign(det)


def _naive_incircle(a, b, c, d) -> np.ndarray:
    ad, bd, cd = a - d, b - d, c - d
    lift = [np.einsum("ij,ij->i", v, v) for v in (ad, bd, cd)]
    det = (lift[0] * (bd[:, 0] * cd[:, 1] - cd[:, 0] * bd[:, 1])
           + lift[1] * (cd[:, 0] * ad[:, 1] - ad[:, 0] * cd[:, 1])
           + lift[2] * (ad[:, 0] * bd[:, 1] - bd[:, 0] * ad[:, 1]))  # fmt: skip
    return np.sign(det)


def _orient_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    p, q, r = np.random.default_rng(SEED).random((3, N, 2))
    return lambda: orient2d_many(p, q, r), lambda: _naive_orient(p, q, r)


def _incircle_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    rng = np.random.default_rng(SEED + 1)
    angles = np.sort(rng.uniform(0, 2 * np.pi, (N, 3)), axis=1)
    a, b, c = (np.column_stack([np.cos(angles[:, k]), np.sin(angles[:, k])]) for k in range(3))
    d = rng.uniform(-1.5, 1.5, (N, 2))
    return lambda: incircle_many(a, b, c, d), lambda: _naive_incircle(a, b, c, d)


def _int64_pair() -> tuple[Callable[[], object], Callable[[], object]]:
    rng = np.random.default_rng(SEED + 2)
    p, q, r = rng.integers(0, 2**40, size=(3, N_INT64, 2)) + np.int64(2**62)
    rounded = [v.astype(np.float64) for v in (p, q, r)]
    return lambda: orient2d_many(p, q, r), lambda: _naive_orient(*rounded)


def cases() -> list[Case]:
    return [
        ("orient2d_many, 1e6 triples (vs naive numpy)", *_orient_pair(), "price of exactness"),
        ("incircle_many, 1e6 quadruples (vs naive numpy)", *_incircle_pair(),
         "price of exactness"),
        ("orient2d_many, 1e5 int64 triples near 2**62", *_int64_pair(), "exact integers"),
    ]  # fmt: skip


if __name__ == "__main__":  # one run of these cases: reference_vs_scipy.py --repeat 1
    import sys
    from pathlib import Path

    from reference_vs_scipy import main

    sys.exit(main(["--repeat", "1", *sys.argv[1:]], only=Path(__file__).stem))
