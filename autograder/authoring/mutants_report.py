"""The mutation analysis as a terminal table, ``mutants.json`` and ``mutants.html``."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import jinja2

from autograder.authoring.mutants_run import TIME_FACTOR, TIME_FLOOR, MutationRun

__all__ = ["format_mutants", "write_mutants"]


def format_mutants(run: MutationRun) -> str:
    """The table ``validate --mutants`` prints, then survivors, idle checks and the verdict."""
    lines = [f"Mutation analysis of {run.assignment} ({len(run.outcomes)} of {run.generated} "
             f"mutants graded, each with {run.cpu_budget:g} s of CPU):", "",
             f"  {'mutant':<40} {'score':>11}  killed by"]
    for o in run.outcomes:
        score = f"{o.score:g}/{o.max_score:g}"
        what = ("EQUIVALENT (same outputs as the model solution)" if o.equivalent else
                ("TOO SLOW, " if o.too_slow else "")
                + f"{len(o.killed_by)} check(s): {', '.join(o.killed_by[:3])}"
                + (" ..." if len(o.killed_by) > 3 else "") if o.killed_by else
                "SURVIVES" + (" (accepted in mutants.toml)" if o.accepted else ""))
        lines.append(f"  {o.mutant.id:<40} {score:>11}  {what}")
    lines.append("")
    counted = run.counted
    lines.append(f"Killed {len(counted) - len(run.survivors)} of {len(counted)} non-equivalent "
                 f"mutants: kill rate {run.kill_rate:.1%}"
                 + (f" (minimum {run.min_kill_rate:.0%})" if run.min_kill_rate is not None else "")
                 + f"; {len(run.outcomes) - len(counted)} equivalent, not counted.")
    slow = sum(o.too_slow for o in run.outcomes)
    if slow:
        lines.append(f"  {slow} mutant(s) TOO SLOW: they spent the whole budget of "
                     f"{run.cpu_budget:g} s of CPU ({TIME_FACTOR:g} times the model solution's, "
                     f"at least {TIME_FLOOR:g} s) and count as killed.")
    for o in run.survivors:
        lines.append(f"  survivor {o.mutant.id}:")
        lines += [f"      {line}" for line in o.mutant.diff.splitlines()[2:]]
        if o.accepted:
            lines += textwrap.wrap("accepted: " + " ".join(o.accepted.split()), width=96,
                                   initial_indent="    ", subsequent_indent="      ")
    if run.idle_checks:
        lines.append("Checks that kill no mutant: " + ", ".join(run.idle_checks))
    lines += [f"Problem: {p}" for p in run.problems]
    if not run.ok and run.min_kill_rate is not None and run.kill_rate < run.min_kill_rate:
        lines.append(f"{run.assignment}: kill rate {run.kill_rate:.1%} is below min_kill_rate "
                     f"{run.min_kill_rate:g}; no check kills "
                     + ", ".join(o.mutant.id for o in run.survivors)
                     + ". Add a check that fails on them (see the diffs above), or list them in "
                     "mutants.toml with the reason they are acceptable.")
    return "\n".join(lines)


def write_mutants(run: MutationRun, out: Path) -> tuple[Path, Path]:
    """``out/mutants.json`` and ``out/mutants.html``."""
    out.mkdir(parents=True, exist_ok=True)
    data = run.to_dict()
    json_path = out / "mutants.json"
    json_path.write_text(json.dumps(data, indent=2), encoding="utf-8")
    env = jinja2.Environment(loader=jinja2.PackageLoader("autograder.authoring", "templates"),
                             autoescape=True, undefined=jinja2.StrictUndefined,
                             trim_blocks=True, lstrip_blocks=True)
    html_path = out / "mutants.html"
    html_path.write_text(env.get_template("mutants.html.j2").render(run=data), encoding="utf-8")
    return json_path, html_path
