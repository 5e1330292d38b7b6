"""Does a long batch cost more per submission at its end than at its start?

Usage: ``python benchmarks/scale.py [--count 1000] [--window 100]``.

Grades ``count`` submissions of a trivial assignment (one cell, one check; the one
``engine_vs_peers.py`` builds) with one :class:`autograder.engine.grader.Grader`, as a
batch of that size does on one slot, and prints for every ``window`` submissions:

* CPU milliseconds per submission of the grader (this process) and of the worker
  (the warm parent and every child it reaped, from ``psutil``);
* the resident memory (RSS, MiB) of the grader and of the warm parent at the end of
  the window, and the number of open file descriptors of the grader;
* wall milliseconds per submission.

The peer of each window is the batch's first 60 submissions (after one warm-up
submission that starts the worker): the last lines print the ratio of the last
window to them, for CPU and wall time per submission and for memory. Flat cost means
ratios near 1. Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _record import Figure, add_json_option, record  # noqa: E402
from engine_vs_peers import write_trivial  # noqa: E402

from autograder.engine.assignment import load_assignment  # noqa: E402
from autograder.engine.grader import Grader  # noqa: E402

MIB = 1 << 20


@dataclass(frozen=True)
class Window:
    """One stretch of the batch: submissions, CPU and wall per submission, memory at its end."""

    first: int
    count: int
    grader_ms: float
    worker_ms: float
    wall_ms: float
    grader_rss: float
    worker_rss: float
    grader_fds: int


def _own_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _worker_cpu(worker: psutil.Process) -> float:
    times = worker.cpu_times()
    return times.user + times.system + times.children_user + times.children_system


def measure(grader: Grader, notebooks: list[Path], first: int, out: Path) -> Window:
    """Grade ``notebooks`` (numbered from ``first``) and sum up what they cost."""
    pid = grader._slot.warm_parent  # the benchmark reads the slot's process on purpose
    assert pid is not None, "the warm-up submission starts the worker"
    worker = psutil.Process(pid)
    me = psutil.Process()
    cpu0, work0, wall0 = _own_cpu(), _worker_cpu(worker), time.perf_counter()
    for k, path in enumerate(notebooks):
        grader.grade(path, id=path.stem, out_dir=out / f"{first + k:04d}")
    n = len(notebooks)
    return Window(first, n, (_own_cpu() - cpu0) * 1000 / n, (_worker_cpu(worker) - work0) * 1000 / n,
                  (time.perf_counter() - wall0) * 1000 / n, me.memory_info().rss / MIB,
                  worker.memory_info().rss / MIB, me.num_fds())


def print_window(w: Window) -> None:
    print(f"  {w.first:5d}-{w.first + w.count - 1:<5d} {w.grader_ms:9.1f} {w.worker_ms:9.1f} "
          f"{w.grader_ms + w.worker_ms:9.1f} {w.wall_ms:9.1f} {w.grader_rss:11.1f} "
          f"{w.worker_rss:11.1f} {w.grader_fds:6d}", flush=True)


def figures(windows: list[Window]) -> list[Figure]:
    """Every window's line, then the last window against the first 60 submissions."""
    found = []
    for w in windows:
        span = f"submissions {w.first}-{w.first + w.count - 1}"
        found += [Figure(f"{span}: CPU (grader + worker)", w.grader_ms + w.worker_ms, "ms"),
                  Figure(f"{span}: grader CPU", w.grader_ms, "ms"),
                  Figure(f"{span}: worker CPU", w.worker_ms, "ms"),
                  Figure(f"{span}: wall", w.wall_ms, "ms"),
                  Figure(f"{span}: grader RSS", w.grader_rss, "MiB"),
                  Figure(f"{span}: worker RSS", w.worker_rss, "MiB"),
                  Figure(f"{span}: grader open descriptors", w.grader_fds, "fds")]
    base, last = windows[0], windows[-1]
    peer = "first 60 submissions"
    return found + [
        Figure("last window: CPU", last.grader_ms + last.worker_ms, "ms", peer,
               base.grader_ms + base.worker_ms),
        Figure("last window: wall", last.wall_ms, "ms", peer, base.wall_ms),
        Figure("last window: grader memory", last.grader_rss, "MiB", peer, base.grader_rss),
        Figure("last window: worker memory", last.worker_rss, "MiB", peer, base.worker_rss),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=1000, help="submissions (default 1000)")
    parser.add_argument("--window", type=int, default=100, help="submissions per line")
    add_json_option(parser, "scale")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-scale-") as tmp:
        work = Path(tmp)
        folder, batch = write_trivial(work, args.count + 1)
        notebooks = sorted(batch.glob("*.ipynb"))
        out = work / "out"
        print(f"one grader, trivial assignment, {args.count} submissions; load average "
              f"{os.getloadavg()[0]:.2f} at start")
        print(f"  {'submissions':<11} {'grader':>9} {'worker':>9} {'CPU ms':>9} {'wall ms':>9} "
              f"{'grader MiB':>11} {'worker MiB':>11} {'fds':>6}")
        with Grader(load_assignment(folder)) as grader:
            grader.grade(notebooks[0], id="warm-up", out_dir=out / "warm-up")
            head = min(60, args.count)
            base = measure(grader, notebooks[1:head + 1], 1, out)
            print_window(base)
            windows = [base]
            for first in range(head + 1, args.count + 1, args.window):
                windows.append(measure(grader, notebooks[first:first + args.window], first, out))
                print_window(windows[-1])
        last = windows[-1]
        print(f"ratio last window / first 60: CPU {(last.grader_ms + last.worker_ms) / (base.grader_ms + base.worker_ms):.2f}x, "
              f"wall {last.wall_ms / base.wall_ms:.2f}x, grader memory "
              f"{last.grader_rss / base.grader_rss:.2f}x, worker memory "
              f"{last.worker_rss / base.worker_rss:.2f}x; load average {os.getloadavg()[0]:.2f} at end")
    record("scale", figures(windows), path=args.json,
           notes=f"One grader, the trivial assignment, {args.count} submissions after one "
           f"warm-up, in windows of {args.window}; CPU and wall ms per submission, memory and "
           "descriptors at each window's end.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
