"""Grade the same batch with the local pool (``--jobs 2``) and with Dask (``--dask local:2``).

Usage: ``python benchmarks/dask_vs_local.py [--count 200] [--workers 2] [--public-only] [--cpu]``.

The batch is ``count`` copies of the hull assignment's sample submissions, each
with a distinct comment cell so that no result is reused. Both runs grade the
same files into fresh folders in this one process, start-up included (the Dask
run starts its ``LocalCluster``, ships the assignment bundle and opens a warm
slot on each worker). Prints each backend's rate, the ratio Dask / local, the
time from start to the first result, and whether both wrote the same
``grades.csv``. Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import nbformat
from _record import Figure, add_json_option, record
from cpu_roles import RoleSampler

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "assignments" / "hull" / "examples"


def build_batch(folder: Path, count: int) -> list[Path]:
    examples = sorted(EXAMPLES.glob("*.ipynb"))
    paths = []
    for i in range(count):
        book = nbformat.read(examples[i % len(examples)], as_version=4)
        book.cells.insert(0, nbformat.v4.new_code_cell(f"# copy {i}"))
        path = folder / f"s{i:04d}.ipynb"
        nbformat.write(book, path)
        paths.append(path)
    return paths


def run(label: str, folder: Path, out: Path, **backend: object) -> dict[str, float]:
    from autograder import api
    from autograder.engine.grader import GradingOptions

    first: list[float] = []
    sampler = RoleSampler().start() if ARGS.cpu else None
    start = time.perf_counter()
    report = api.grade("hull", [folder], out=out, progress=False,
                       options=GradingOptions(public_only=ARGS.public_only),
                       on_result=lambda r: first.append(time.perf_counter()) if not first else None,
                       **backend)  # type: ignore[arg-type]
    seconds = time.perf_counter() - start
    figures = {"seconds": seconds, "rate": len(report.results) / seconds,
               "first": (first[0] - start) if first else float("nan"), "failed": len(report.failed)}
    print(f"{label:<22} {seconds:8.1f} s  {figures['rate']:6.2f} submissions/s  "
          f"first result after {figures['first']:5.1f} s  errors {figures['failed']}", flush=True)
    if sampler is not None:
        threads = sampler.client_threads()
        count = max(1, len(report.results))
        for role, cpu in sorted(sampler.stop().items()):
            figures[f"cpu {role}"] = cpu / count
            print(f"    CPU {role:<20} {cpu:7.1f} s  {cpu / count:6.3f} s/submission", flush=True)
        print(f"    processes seen: {sampler.processes}", flush=True)
        for name, cpu in sorted(threads.items(), key=lambda kv: -kv[1])[:6]:
            print(f"      client thread {name:<28} {cpu:6.1f} s", flush=True)
    return figures


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="dask-vs-local-") as tmp:
        work = Path(tmp)
        (work / "subs").mkdir()
        build_batch(work / "subs", ARGS.count)
        print(f"{ARGS.count} hull submissions, {'public' if ARGS.public_only else 'all'} checks, "
              f"{ARGS.workers} slots each", flush=True)
        local = run(f"--jobs {ARGS.workers}", work / "subs", work / "local", jobs=ARGS.workers)
        dask = run(f"--dask local:{ARGS.workers}", work / "subs", work / "dask",
                   dask=f"local:{ARGS.workers}")
        same = (work / "local" / "grades.csv").read_text() == (work / "dask" / "grades.csv").read_text()
        print(f"ratio dask/local (rate): {dask['rate'] / local['rate']:.2f}   "
              f"first result: local {local['first']:.1f} s, dask {dask['first']:.1f} s   "
              f"same grades.csv: {same}")
    record("dask_vs_local", figures(local, dask, same), path=ARGS.json,
           notes=f"{ARGS.count} hull submissions, {'public' if ARGS.public_only else 'all'} "
           f"checks, {ARGS.workers} slots each, start-up included.")


def figures(local: dict[str, float], dask: dict[str, float], same: bool) -> list[Figure]:
    """Both runs' figures; Dask's against the local pool's."""
    units = {"seconds": "s", "rate": "submissions/s", "first": "s to the first result",
             "failed": "errors"}
    found = []
    for key in local:
        unit = units.get(key, "CPU s per submission")
        found.append(Figure(f"--jobs {ARGS.workers}: {key}", local[key], unit))
        found.append(Figure(f"--dask local:{ARGS.workers}: {key}", dask[key], unit,
                            f"--jobs {ARGS.workers}", local[key]))
    return found + [Figure("same grades.csv", same, "")]


if __name__ == "__main__":  # LocalCluster spawns worker processes that re-import this file
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--public-only", action="store_true")
    parser.add_argument("--cpu", action="store_true",
                        help="also print CPU seconds per process role (see cpu_roles.py)")
    add_json_option(parser, "dask_vs_local")
    ARGS = parser.parse_args()
    main()
