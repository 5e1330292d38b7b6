"""Time each ``reference`` routine against its SciPy counterpart in the same run.

Usage: ``python benchmarks/reference_vs_scipy.py [--repeat N]``. Prints one row
per case: our best time, SciPy's best time, the ratio (ours / SciPy) and the
target from the issue. Cases live in ``reference_cases_*.py`` beside this file;
each defines ``cases() -> [(name, ours, scipy_peer, target), ...]`` and, run as a
script (``python benchmarks/reference_cases_geometry.py``), times its own cases
once through :func:`main`.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path
from typing import Callable

from _record import Figure, add_json_option, record

HERE = Path(__file__).resolve().parent
Case = tuple[str, Callable[[], object], Callable[[], object], str]


def best_of(fn: Callable[[], object], repeat: int) -> float:
    """The fastest of ``repeat`` runs, in seconds (the least disturbed by other load)."""
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def load_cases(pattern: str = "reference_cases_*.py") -> tuple[list[Case], list[Figure]]:
    """The cases of the files matching ``pattern``, and their memory peaks (printed here)."""
    cases, peaks = [], []
    for path in sorted(HERE.glob(pattern)):
        spec = importlib.util.spec_from_file_location(path.stem, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        cases += module.cases()
        if hasattr(module, "memory_peaks"):
            for name, ours, theirs in module.memory_peaks():
                print(f"memory peak  {name:<48} ours {ours / 2**20:8.1f} MiB   "
                      f"scipy {theirs / 2**20:8.1f} MiB   ratio {ours / max(theirs, 1):5.2f}")
                peaks.append(Figure(f"{name}: memory peak", ours / 2**20, "MiB", "SciPy",
                                    max(theirs, 1) / 2**20))
    return cases, peaks


def main(argv: list[str] | None = None, *, only: str | None = None) -> int:
    """Time every case, or with ``only`` (a file's stem, ``reference_cases_geometry``) its cases."""
    name = only or "reference_vs_scipy"
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per case (best is kept)")
    add_json_option(parser, name)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(HERE.parent))
    cases, figures = load_cases(f"{only}.py" if only else "reference_cases_*.py")
    print(f"{'case':<52} {'ours':>9} {'scipy':>9} {'ratio':>7}  target")
    for case, ours, theirs, target in cases:
        t_ours = best_of(ours, args.repeat)
        t_scipy = best_of(theirs, args.repeat)
        print(f"{case:<52} {t_ours:8.3f}s {t_scipy:8.3f}s {t_ours / t_scipy:7.2f}  {target}")
        figures.append(Figure(f"{case} (target: {target})", t_ours, "s", "SciPy", t_scipy))
    record(name, figures, path=args.json,
           notes=f"Best of {args.repeat} runs per case; ratio = ours / SciPy (for the exact "
           "predicates the peer is the naive floating-point formula in NumPy).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
