"""Time each ``reference`` routine against its SciPy counterpart in the same run.

Usage: ``python benchmarks/reference_vs_scipy.py [--repeat N]``. Prints one row
per case: our best time, SciPy's best time, the ratio (ours / SciPy) and the
target from the issue. Cases live in ``reference_cases_*.py`` beside this file;
each defines ``cases() -> [(name, ours, scipy_peer, target), ...]``.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path
from typing import Callable

HERE = Path(__file__).resolve().parent


def best_of(fn: Callable[[], object], repeat: int) -> float:
    """The fastest of ``repeat`` runs, in seconds (the least disturbed by other load)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def load_cases() -> list[tuple[str, Callable[[], object], Callable[[], object], str]]:
    cases = []
    for path in sorted(HERE.glob("reference_cases_*.py")):
        spec = importlib.util.spec_from_file_location(path.stem, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        cases += module.cases()
        if hasattr(module, "memory_peaks"):
            for name, ours, theirs in module.memory_peaks():
                print(f"memory peak  {name:<48} ours {ours / 2**20:8.1f} MiB   "
                      f"scipy {theirs / 2**20:8.1f} MiB   ratio {ours / max(theirs, 1):5.2f}")
    return cases


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per case (best is kept)")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(HERE.parent))
    cases = load_cases()
    print(f"{'case':<52} {'ours':>9} {'scipy':>9} {'ratio':>7}  target")
    for name, ours, theirs, target in cases:
        t_ours = best_of(ours, args.repeat)
        t_scipy = best_of(theirs, args.repeat)
        print(f"{name:<52} {t_ours:8.3f}s {t_scipy:8.3f}s {t_ours / t_scipy:7.2f}  {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
