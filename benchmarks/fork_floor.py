"""What a fresh process per submission costs at least: fork and exit of a warm parent.

Usage: ``python benchmarks/fork_floor.py [--count 40]``.

The worker forks one child per submission from a warm parent that imported numpy,
scipy, matplotlib and IPython (``autograder/worker/__main__.py``); the child runs the
notebook and exits. The kernel's part of that (copying the parent's page tables,
copying on write the pages the child touches, tearing the address space down at exit)
grows with the parent's memory. This prints, in one run, the CPU milliseconds per
fork of

* a bare parent (this interpreter before any heavy import; the peer),
* the warm parent (the worker's imports and its IPython shell),
* the warm parent whose child also runs a one-line cell in the IPython shell,
* the warm parent whose child runs a cell that allocates 300,000 small objects,
  without and then with ``gc.freeze()`` in the parent before the fork (what the
  worker does: the child's full garbage collections then skip, and so neither walk
  nor copy on write, every object the parent made),
* the warm parent whose child runs the hull solution's code cells
  (``assignments/hull/examples/solution.ipynb``) twice: the first run is what a
  submission's notebook costs in a fresh fork, the second, in the same child, what
  the same cells cost once the pages they touch are the child's own (the bare
  floor's case: a warm process that ran them before); with the minor page faults of
  each run, the copies on write of the parent's pages among them; once with the
  parent in 4 KiB pages and once after the collapse into huge pages below,
* the warm parent after :func:`autograder.worker.hugepages.collapse` (what the worker
  does once it has forked 50 children), bare and with one cell: the fork copies one
  page-table entry per 2 MiB instead of per 4 KiB where its heap could be collapsed,

split into the parent's share (``fork``) and the child's (everything to its exit),
with the parent's resident memory and the ratio of each to the bare parent. The
sandbox, the grader and the checks come on top. Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import gc
import os
import resource
import statistics
import sys
import time
from pathlib import Path
from typing import Callable

from _record import Figure, add_json_option, record


def _cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def _rss_mib() -> float:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / (1 << 20)


def forks(count: int, body: Callable[[], object]) -> tuple[float, float, float]:
    """Parent CPU, child CPU and wall milliseconds per fork of a child running ``body``."""
    parent, child, wall = (_cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN),
                           time.perf_counter())
    for _ in range(count):
        pid = os.fork()
        if pid == 0:
            try:
                body()
            finally:
                os._exit(0)
        os.waitpid(pid, 0)
    return (1000 * (_cpu(resource.RUSAGE_SELF) - parent) / count,
            1000 * (_cpu(resource.RUSAGE_CHILDREN) - child) / count,
            1000 * (time.perf_counter() - wall) / count)


def cells_twice(count: int, shell: object, cells: list[str], folder: Path,
                ) -> list[tuple[float, float, float, float]]:
    """Per fork: the child's CPU ms and minor page faults running ``cells`` in ``shell``
    (an IPython shell made before the fork), then the same running them again."""
    rows = []
    for _ in range(count):
        reader, writer = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                os.close(reader)
                os.chdir(folder)  # the notebook reads its data relative to its folder
                null = os.open(os.devnull, os.O_WRONLY)
                os.dup2(null, 1)
                os.dup2(null, 2)
                sys.stdout = sys.stderr = open(os.devnull, "w")  # noqa: SIM115
                found = []
                for _run in range(2):
                    before = time.process_time(), resource.getrusage(resource.RUSAGE_SELF)
                    for source in cells:
                        shell.run_cell(source, store_history=False)  # type: ignore[attr-defined]
                    after = time.process_time(), resource.getrusage(resource.RUSAGE_SELF)
                    found += [1000 * (after[0] - before[0]),
                              float(after[1].ru_minflt - before[1].ru_minflt)]
                os.write(writer, " ".join(map(str, found)).encode())
            finally:
                os._exit(0)
        os.close(writer)
        with os.fdopen(reader, "rb") as answer:
            said = answer.read().split()
        os.waitpid(pid, 0)
        if len(said) != 4:
            raise SystemExit("fork_floor: the child that runs the hull solution's cells died "
                             "before it reported; run the solution notebook on its own to see why")
        first_ms, first_faults, again_ms, again_faults = map(float, said)
        rows.append((first_ms, first_faults, again_ms, again_faults))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=40, help="forks per line (default 40)")
    add_json_option(parser, "fork_floor")
    args = parser.parse_args(argv)
    print(f"load average {os.getloadavg()[0]:.2f}; {args.count} forks per line; ms per fork")
    print(f"  {'parent':<34} {'RSS MiB':>8} {'fork':>7} {'child':>7} {'CPU':>7} {'wall':>7} "
          f"{'CPU ratio':>10}")
    rows: list[tuple[str, float, tuple[float, float, float]]] = [
        ("bare interpreter", _rss_mib(), forks(args.count, lambda: None))]

    import matplotlib  # the warm parent's imports, as autograder.worker makes them
    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401
    import matplotlib.tri  # noqa: F401
    import numpy  # noqa: F401
    import scipy.interpolate  # noqa: F401
    import scipy.linalg  # noqa: F401
    import scipy.spatial  # noqa: F401
    import scipy.special  # noqa: F401

    from autograder.worker import execute, hugepages

    shell = execute.make_shell()
    execute.warm_up(shell)
    rows.append(("warm parent", _rss_mib(), forks(args.count, lambda: None)))
    rows.append(("warm parent, child runs one cell", _rss_mib(), forks(
        args.count, lambda: shell.run_cell("def double(x):\n    return 2 * x\n",
                                           store_history=False))))
    allocate = "points = [(i, 0.5 * i, [i]) for i in range(300_000)]\n"
    gc.unfreeze()
    rows.append(("warm parent, allocating cell", _rss_mib(), forks(
        max(1, args.count // 4), lambda: shell.run_cell(allocate, store_history=False))))
    gc.freeze()
    rows.append(("  the same after gc.freeze()", _rss_mib(), forks(
        max(1, args.count // 4), lambda: shell.run_cell(allocate, store_history=False))))
    import nbformat

    hull = Path(__file__).resolve().parent.parent / "assignments" / "hull"
    book = nbformat.read(hull / "examples" / "solution.ipynb", as_version=4)
    code = [cell.source for cell in book.cells if cell.cell_type == "code"]
    runs = cells_twice(max(1, args.count // 4), shell, code, hull)
    twice = [statistics.median(run[k] for run in runs) for k in range(4)]
    collapsed = hugepages.collapse()
    runs_huge = cells_twice(max(1, args.count // 4), shell, code, hull)
    twice_huge = [statistics.median(run[k] for run in runs_huge) for k in range(4)]
    rows.append(("warm parent in huge pages", _rss_mib(), forks(args.count, lambda: None)))
    rows.append(("  child runs one cell", _rss_mib(), forks(
        args.count, lambda: shell.run_cell("def double(x):\n    return 2 * x\n",
                                           store_history=False))))
    bare = sum(rows[0][2][:2])
    for label, rss, (parent, child, wall) in rows:
        print(f"  {label:<34} {rss:8.1f} {parent:7.1f} {child:7.1f} {parent + child:7.1f} "
              f"{wall:7.1f} {(parent + child) / bare:9.1f}x", flush=True)
    for where, (first, faults, again, again_faults) in (("", twice),
                                                         (", parent in huge pages", twice_huge)):
        extra = max(1.0, faults - again_faults)
        print(f"hull solution's cells in the child{where} (medians of {len(runs)} forks): "
              f"first run {first:.1f} ms CPU, {faults:.0f} minor faults; again in the same "
              f"child {again:.1f} ms, {again_faults:.0f} faults: the fresh fork costs "
              f"{first - again:.1f} ms more ({(first - again) * 1000 / extra:.1f} us per "
              "extra fault)")
    plain, frozen = sum(rows[3][2][:2]), sum(rows[4][2][:2])
    print(f"ratio allocating cell, without / with gc.freeze(): {plain / frozen:.2f}x CPU")
    print(f"huge pages: {collapsed / (1 << 20):.0f} MiB collapsed "
          f"(autograder.worker.hugepages, after the warm parent's 50th child); "
          f"ratio warm parent, 4 KiB / huge pages: {sum(rows[1][2][:2]) / sum(rows[5][2][:2]):.2f}x "
          f"bare child, {sum(rows[2][2][:2]) / sum(rows[6][2][:2]):.2f}x with one cell")
    found = figures(rows, collapsed) + [
        Figure("hull solution's cells, first run in the child: CPU", twice[0], "ms",
               "again in the same child", twice[2]),
        Figure("hull solution's cells, first run in the child: minor faults", twice[1],
               "faults", "again in the same child", twice[3]),
        Figure("hull solution's cells, first run in the child, parent in huge pages: CPU",
               twice_huge[0], "ms", "again in the same child", twice_huge[2]),
        Figure("hull solution's cells, first run in the child, parent in huge pages: "
               "minor faults", twice_huge[1], "faults", "again in the same child",
               twice_huge[3])]
    record("fork_floor", found, path=args.json,
           notes=f"{args.count} forks per line ({max(1, args.count // 4)} for the allocating "
           "cell); ms of CPU per fork, the parent's share (fork) and the child's (to its exit).")
    return 0


def figures(rows: list[tuple[str, float, tuple[float, float, float]]],
            collapsed: int) -> list[Figure]:
    """The printed table and ratios as figures; an indented line is named after the one above."""
    found, bare, above = [], sum(rows[0][2][:2]), ""
    for index, (label, rss, (parent, child, wall)) in enumerate(rows):
        above = label if not label.startswith(" ") else above
        name = label if not label.startswith(" ") else f"{above}, {label.strip()}"
        peer = ("bare interpreter", bare) if index else ()
        found += [Figure(f"{name}: CPU", parent + child, "ms", *peer),
                  Figure(f"{name}: fork (parent)", parent, "ms"),
                  Figure(f"{name}: child", child, "ms"),
                  Figure(f"{name}: wall", wall, "ms"),
                  Figure(f"{name}: parent RSS", rss, "MiB")]
    cpu = [sum(times[:2]) for _, _, times in rows]
    return found + [
        Figure("allocating cell, without gc.freeze(): CPU", cpu[3], "ms", "with gc.freeze()",
               cpu[4]),
        Figure("huge pages: collapsed", collapsed / (1 << 20), "MiB"),
        Figure("warm parent in 4 KiB pages, bare child: CPU", cpu[1], "ms", "in huge pages",
               cpu[5]),
        Figure("warm parent in 4 KiB pages, one cell: CPU", cpu[2], "ms", "in huge pages",
               cpu[6]),
    ]


if __name__ == "__main__":
    sys.exit(main())
