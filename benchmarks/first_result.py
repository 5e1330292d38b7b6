"""Time from the command's start to its first ``results.json``, for ``--jobs 1`` and ``--jobs 2``.

Usage: ``python benchmarks/first_result.py [--runs 3] [--jobs 1 2] [--python PATH]``.

Runs ``autograder grade hull assignments/hull/examples --out TMP --jobs N --no-progress``
``--runs`` times per N and prints, per run: the seconds to the first result (the
folder is polled every 10 ms), to the end of the command, and the CPU seconds of
the command and every process it reaped (``RUSAGE_CHILDREN``), then the median of
each. ``--python`` runs another installation (another checkout's venv) to compare
two versions on the same machine in one sitting. Wall-clock figures mean something
only on an idle machine (check ``uptime``); CPU seconds move less with load.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _record import Figure, add_json_option, record

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent / "assignments" / "hull" / "examples"


def one_run(python: str, jobs: int) -> tuple[float, float, float]:
    """(seconds to the first result, seconds to the end, CPU seconds) of one command."""
    with tempfile.TemporaryDirectory(prefix="first-result-") as tmp:
        out = Path(tmp) / "out"
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        proc = subprocess.Popen([python, "-m", "autograder", "grade", "hull", str(EXAMPLES),
                                 "--out", str(out), "--jobs", str(jobs), "--no-progress"],
                                cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        first = None
        while proc.poll() is None:
            if first is None and any(out.glob("*/results.json")):
                first = time.perf_counter() - start
            time.sleep(0.01)
        end = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            assert proc.stderr is not None
            raise SystemExit(f"--jobs {jobs} exited {proc.returncode}: "
                             f"{proc.stderr.read().decode()[-2000:]}")
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
        return (first if first is not None else end), end, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per --jobs value (default: 3)")
    parser.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--python", default=sys.executable,
                        help="the Python whose autograder is run (default: this one)")
    add_json_option(parser, "first_result")
    args = parser.parse_args()
    print(f"{'jobs':>4} {'first result':>13} {'end':>8} {'CPU':>8}   ({args.python})")
    figures = []
    for jobs in args.jobs:
        runs = [one_run(args.python, jobs) for _ in range(args.runs)]
        for first, end, cpu in runs:
            print(f"{jobs:>4} {first:11.2f} s {end:6.2f} s {cpu:6.2f} s")
        first, end, cpu = (statistics.median(r[k] for r in runs) for k in range(3))
        print(f"{jobs:>4} {first:11.2f} s {end:6.2f} s {cpu:6.2f} s   median of {len(runs)}")
        figures += [Figure(f"--jobs {jobs}: first result (median)", first, "s"),
                    Figure(f"--jobs {jobs}: end (median)", end, "s"),
                    Figure(f"--jobs {jobs}: CPU (median)", cpu, "s")]
    record("first_result", figures, path=args.json,
           notes=f"`autograder grade hull assignments/hull/examples`, medians of {args.runs} "
           f"runs per --jobs value, with {args.python}.")


if __name__ == "__main__":
    main()
