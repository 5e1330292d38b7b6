"""Mutation analysis of every shipped assignment: mutants, kill rate, seconds per mutant.

Runs :func:`autograder.authoring.mutants_run.run_mutants` (what ``autograder validate
ASSIGNMENT --mutants`` runs after the examples) on each assignment with ``--jobs 2``
and prints one row per assignment: mutants generated and graded, equivalent ones,
too slow ones (spent their CPU budget; counted as killed), kill rate over the
non-equivalent ones, survivors (and how many of them ``mutants.toml`` accepts), and
wall seconds per graded mutant (the reference's own grading and the equivalence
probes of the survivors included).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from _record import ROOT, Figure, add_json_option, record  # imported first: the load at start

sys.path.insert(0, str(ROOT))

from autograder.authoring.mutants_run import run_mutants  # noqa: E402
from autograder.engine.assignment import load_assignment  # noqa: E402

SHIPPED = ("hull", "bezier", "delaunay", "spline_car", "approximation", "interpolation")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("assignments", nargs="*", default=list(SHIPPED))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--max-mutants", type=int, default=None,
                        help="mutants per assignment (default: each assignment's [mutants] max)")
    add_json_option(parser, "validate_mutants")
    args = parser.parse_args()
    print(f"{'assignment':<15} {'generated':>9} {'graded':>6} {'equiv':>5} {'too slow':>8} "
          f"{'kill rate':>9} {'survivors':>9} {'accepted':>8} {'s/mutant':>8}")
    figures = []
    for name in args.assignments:
        assignment = load_assignment(ROOT / "assignments" / name)
        with tempfile.TemporaryDirectory(prefix=f"mutants-{name}-") as work:
            run = run_mutants(assignment, Path(work), jobs=args.jobs, max_mutants=args.max_mutants)
        graded = len(run.outcomes)
        per = run.seconds / graded if graded else 0.0
        equivalent = graded - len(run.counted)
        slow = sum(o.too_slow for o in run.outcomes)
        accepted = sum(o.accepted is not None for o in run.survivors)
        print(f"{name:<15} {run.generated:>9} {graded:>6} {equivalent:>5} {slow:>8} "
              f"{run.kill_rate:>9.1%} {len(run.survivors):>9} {accepted:>8} {per:>8.2f}")
        figures += [Figure(f"{name}: mutants graded", graded, "mutants"),
                    Figure(f"{name}: kill rate", run.kill_rate, "fraction"),
                    Figure(f"{name}: seconds per mutant (--jobs {args.jobs})", per, "s")]
    record("validate_mutants", figures, path=args.json,
           notes=f"`run_mutants` (validate --mutants without the examples), --jobs {args.jobs}.")


if __name__ == "__main__":
    main()
