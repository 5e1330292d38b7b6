"""Grade the same batch of hull submissions with this engine and with ``nbgrader autograde``.

Usage: ``python benchmarks/grade_vs_nbgrader.py [--count 120] [--jobs 2] [--skip-nbgrader]``.

The batch is built from the hull assignment's sample submissions (the solution
and the typical wrong answers), each pasted into the released student template
so that both engines read identical nbgrader-format files; every copy differs
by a comment so nothing is served from a cache. Prints submissions per second
for both engines (start-up included) and the ratio.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import nbformat
from _record import Figure, add_json_option, record

ROOT = Path(__file__).resolve().parents[1]
HULL = ROOT / "assignments" / "hull"


def example_code(path: Path) -> str:
    book = nbformat.read(path, as_version=4)
    return "\n\n".join(c.source for c in book.cells if c.cell_type == "code")


def build_batch(folder: Path, count: int) -> list[Path]:
    """``count`` submissions laid out as nbgrader expects: ``<student>/hull/hull.ipynb``."""
    from autograder.authoring.release import student_template
    from autograder.engine.assignment import load_assignment

    template = student_template(load_assignment(HULL))
    examples = sorted((HULL / "examples").glob("*.ipynb"))
    paths = []
    for k in range(count):
        book = nbformat.from_dict(template)
        code = example_code(examples[k % len(examples)])
        for cell in book.cells:
            grade_id = cell.metadata.get("nbgrader", {}).get("grade_id")
            if grade_id == "orientation":
                cell.source = f"# submission {k}\n{code}"
            elif grade_id == "convex_hull":
                cell.source = "# (written in the cell above)"
        target = folder / f"s{k:04d}" / "hull" / "hull.ipynb"
        target.parent.mkdir(parents=True)
        nbformat.write(book, target)
        paths.append(target)
    return paths


def run_ours(batch: Path, out: Path, jobs: int, *extra: str) -> float:
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "autograder", "grade", str(HULL), str(batch),
                           "--out", str(out), "--jobs", str(jobs), "--no-progress", *extra],
                          capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"autograder failed:\n{proc.stderr[-3000:]}")
    print("  " + proc.stdout.strip().replace("\n", "\n  "))
    return elapsed


def run_nbgrader(batch: Path, course: Path) -> float:
    (course / "source" / "hull").mkdir(parents=True)
    shutil.copy(HULL / "hull.ipynb", course / "source" / "hull" / "hull.ipynb")
    shutil.copytree(HULL / "data", course / "source" / "hull" / "data")
    (course / "nbgrader_config.py").write_text(
        f'c = get_config()\nc.CourseDirectory.course_id = "bench"\n'
        f'c.CourseDirectory.root = {str(course)!r}\n')
    subprocess.run(["nbgrader", "generate_assignment", "hull", "--force"], cwd=course,
                   check=True, capture_output=True)
    for student in sorted(batch.iterdir()):
        target = course / "submitted" / student.name / "hull"
        shutil.copytree(student / "hull", target)
        shutil.copytree(HULL / "data", target / "data")
    start = time.perf_counter()
    proc = subprocess.run(["nbgrader", "autograde", "hull", "--force"], cwd=course,
                          capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if proc.returncode != 0:
        print(f"  nbgrader exited {proc.returncode}: {proc.stderr[-1500:]}")
    return elapsed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=120, help="submissions in the batch")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--skip-nbgrader", action="store_true",
                        help="time only this engine (nbgrader takes a few seconds per notebook)")
    add_json_option(parser, "grade_vs_nbgrader")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-") as tmp:
        work = Path(tmp)
        batch = work / "submitted"
        build_batch(batch, args.count)
        print(f"batch: {args.count} hull submissions (solution and typical wrong answers)")
        # Every check (28 items, hidden sets up to 2000 points, run by the student's
        # code), then only the public checks: small inputs, like the two test cells
        # nbgrader runs, so that line compares the engines on equal work.
        rates, figures = {}, []
        for label, extra in (("all checks", ()), ("public checks", ("--public-only",))):
            seconds = run_ours(batch, work / f"results-{len(rates)}", args.jobs, *extra)
            rates[label] = args.count / seconds
            print(f"autograder, {label:<14} (--jobs {args.jobs}): {seconds:7.1f} s  "
                  f"{rates[label]:7.2f} submissions/s")
            figures.append(Figure(f"autograder, {label} (--jobs {args.jobs}): time", seconds, "s"))
        peer: tuple[str, float] | tuple[()] = ()
        if not args.skip_nbgrader:
            theirs = run_nbgrader(batch, work / "course")
            theirs_rate = args.count / theirs
            print(f"nbgrader autograde (its test cells):  {theirs:7.1f} s  {theirs_rate:7.2f} submissions/s")
            for label, rate in rates.items():
                print(f"ratio, autograder {label} / nbgrader: {rate / theirs_rate:.1f}x")
            figures.append(Figure("nbgrader autograde (its test cells): time", theirs, "s"))
            peer = ("nbgrader autograde", theirs_rate)
        figures += [Figure(f"autograder, {label}: rate", rate, "submissions/s", *peer)
                    for label, rate in rates.items()]
    record("grade_vs_nbgrader", figures, path=args.json,
           notes=f"{args.count} hull submissions (solution and typical wrong answers) in the "
           "released template, start-up included"
           + ("; nbgrader skipped." if args.skip_nbgrader else "."))
    return 0


if __name__ == "__main__":
    sys.exit(main())
