"""`autograder validate --mutants`: mutants generated deterministically, graded, classified.

The assignment here is written from scratch: ``total(xs)`` sums a list with a loop.
Its mutants include ``s = 1`` (a wrong start), ``s = x`` (the accumulation dropped),
``s -= x`` and the loop reversed, which gives the same sums on every list of
integers (an equivalent mutant). A *weak* check (``total([1, 2, 3]) > 0``) lets
``s = x`` live, and the analysis must say so.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from autograder.authoring.mutants import generate_mutants, graded_functions
from autograder.authoring.mutants_report import format_mutants, write_mutants
from autograder.authoring.mutants_run import PROBE, TIME_FLOOR, MutationRun, run_mutants
from autograder.engine.assignment import load_assignment

ROOT = Path(__file__).resolve().parents[2]
TOTAL = "def total(xs):\n    s = 0\n    for x in xs:\n        s += x\n    return s\n"
WEAK = ("def test_total_is_positive(student):\n"
        "    assert student.total([1, 2, 3]) > 0, 'the sum of 1, 2, 3 is positive'\n")
STRONG = ("def test_total_sums(student):\n"
          "    assert student.total([1, 2, 3]) == 6, 'total([1, 2, 3]) must be 6'\n")
#: ``total`` through a helper, beside a function no check reaches and a plot
HELPED = ("def add(a, b):\n    return a + b\n\n"
          "def total(xs):\n    s = 0\n    for x in xs:\n        s = add(s, x)\n    return s\n\n"
          "def unused(x):\n    return x * 2\n\n"
          "def draw(xs):\n    fig, ax = plt.subplots(figsize=(4, 3))\n"
          "    ax.plot(xs, lw=2, alpha=0.5)\n    ax.set_xlim(0, 9)\n    return fig\n")
#: ``total`` with a while loop: ``i = 1`` for ``i += 1`` never ends
WHILE = ("def total(xs):\n    s, i = 0, 0\n    while i < len(xs):\n        s += xs[i]\n"
         "        i += 1\n    return s\n")


def write_total(root: Path, checks: dict[str, str], toml_extra: str = "",
                solution: str = TOTAL) -> Path:
    """An assignment whose model solution is ``total`` (``solution``: its code);
    ``checks`` are public check files."""
    folder = root / "total"
    for part in ("checks/public", "checks/hidden", "examples"):
        (folder / part).mkdir(parents=True)
    (folder / "assignment.toml").write_text(
        '[assignment]\nname = "total"\ntitle = "Sum it"\nnotebook = "total.ipynb"\n' + toml_extra)
    cell = nbformat.v4.new_code_cell(
        "### BEGIN SOLUTION\n" + solution + "### END SOLUTION",
        metadata={"nbgrader": {"grade_id": "total", "solution": True, "grade": False,
                               "locked": False, "schema_version": 3}})
    nbformat.write(nbformat.v4.new_notebook(cells=[cell]), folder / "total.ipynb")
    (folder / "examples" / "expected.toml").write_text("[template]\nmin = 0\nmax = 0\n")
    for name, text in checks.items():
        (folder / "checks" / "public" / name).write_text(text)
    return folder


def by_operator(run: MutationRun, operator: str) -> list:
    return [o for o in run.outcomes if o.mutant.operator == operator]


def test_generation_is_deterministic_and_covers_the_numerical_operators(tmp_path: Path) -> None:
    nb = nbformat.read(str(write_total(tmp_path, {"test_w.py": WEAK}) / "total.ipynb"), as_version=4)
    first, second = generate_mutants(nb), generate_mutants(nb)
    assert [(m.id, m.diff) for m in first] == [(m.id, m.diff) for m in second]
    operators = {m.operator for m in first}
    assert {"constant", "drop-accumulation", "operator", "reversed-loop", "ordering"} <= operators
    dropped = next(m for m in first if m.operator == "drop-accumulation")
    assert "-        s += x\n+        s = x\n" in dropped.diff
    hull = nbformat.read(str(ROOT / "assignments/hull/hull.ipynb"), as_version=4)
    ids = [m.id for m in generate_mutants(hull)]
    assert ids == [m.id for m in generate_mutants(hull)] and len(ids) == len(set(ids))
    assert {m.split("-")[0] for m in ids} == {"orientation", "convex_hull"}


@pytest.fixture(scope="module")
def weak_run(tmp_path_factory: pytest.TempPathFactory) -> MutationRun:
    root = tmp_path_factory.mktemp("weak")
    folder = write_total(root, {"test_weak.py": WEAK})
    return run_mutants(load_assignment(folder), root / "work", jobs=2)


def test_a_missing_check_leaves_the_dropped_accumulation_alive(weak_run: MutationRun,
                                                               tmp_path: Path) -> None:
    dropped = by_operator(weak_run, "drop-accumulation")
    assert len(dropped) == 1 and dropped[0].killed_by == () and not dropped[0].equivalent
    assert dropped[0] in weak_run.survivors
    flipped = next(o for o in by_operator(weak_run, "operator") if "s -= x" in o.mutant.diff)
    assert flipped.killed_by == ("total_is_positive",)
    json_path, html_path = write_mutants(weak_run, tmp_path / "out")
    data = json.loads(json_path.read_text())
    entry = next(m for m in data["mutants"] if m["id"] == dropped[0].mutant.id)
    assert entry["killed_by"] == [] and entry["equivalent"] is False
    assert entry["function"] == "total" and "s = x" in entry["diff"]
    assert dropped[0].mutant.id in data["survivors"]
    assert dropped[0].mutant.id in html_path.read_text()


def test_equivalent_mutants_are_reported_apart(weak_run: MutationRun) -> None:
    reversed_loop = by_operator(weak_run, "reversed-loop")
    assert len(reversed_loop) == 1 and reversed_loop[0].equivalent
    assert reversed_loop[0] not in weak_run.counted
    killed = len(weak_run.counted) - len(weak_run.survivors)
    assert weak_run.kill_rate == killed / len(weak_run.counted) < 1
    assert "EQUIVALENT" in format_mutants(weak_run)


@pytest.mark.slow
def test_min_kill_rate_fails_the_cli_naming_the_survivors(tmp_path: Path) -> None:
    folder = write_total(tmp_path / "src", {"test_weak.py": WEAK},
                         "\n[mutants]\nmin_kill_rate = 0.9\n")
    out = tmp_path / "report"
    proc = subprocess.run([sys.executable, "-m", "autograder", "validate", str(folder),
                           "--mutants", "--jobs", "2", "--out", str(out)],
                          capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    data = json.loads((out / "mutants.json").read_text())
    survivors = data["survivors"]
    assert survivors and data["kill_rate"] < 0.9
    assert "is below min_kill_rate 0.9" in proc.stdout
    assert all(s in proc.stdout.split("no check kills")[1] for s in survivors)
    assert (out / "mutants.html").read_text().startswith("<!doctype html>")


@pytest.mark.slow
def test_the_strong_check_kills_every_non_equivalent_mutant(tmp_path: Path) -> None:
    folder = write_total(tmp_path, {"test_strong.py": STRONG}, "\n[mutants]\nmin_kill_rate = 1\n")
    run = run_mutants(load_assignment(folder), tmp_path / "work", jobs=2)
    assert run.ok and run.kill_rate == 1.0 and run.survivors == ()
    assert [o.mutant.operator for o in run.outcomes if o.equivalent] == ["reversed-loop"]


def test_helpers_the_checks_reach_are_mutated_and_style_keywords_are_not(tmp_path: Path) -> None:
    folder = write_total(tmp_path, {"test_s.py": STRONG}, solution=HELPED)
    nb = nbformat.read(str(folder / "total.ipynb"), as_version=4)
    assert graded_functions(nb, {"total"}) == {"total", "add"}
    assert graded_functions(nb, {"draw"}) == {"draw"}
    mutants = generate_mutants(nb)
    assert any(m.function == "add" and "a - b" in m.diff for m in mutants)
    drawn = [m.diff for m in mutants if m.function == "draw"]
    assert any("set_xlim(1, 9)" in d for d in drawn)  # an axis limit is content, not style
    assert not any("figsize=(5" in d or "lw=3" in d or "alpha=1.5" in d for d in drawn)


def test_the_probe_compares_figures_by_their_pixels() -> None:
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    probe: dict = {}
    exec(PROBE.replace("{wraps}", ""), probe)  # the probe cell's own code, run here
    same = probe["_ng_same"]

    def line(width: float) -> object:
        fig, ax = plt.subplots(figsize=(3, 2))
        ax.plot([0, 1, 3], lw=width)
        return fig

    try:
        assert same(line(1), line(1)), "two figures that draw the same picture are the same"
        assert not same(line(1), line(2)), "a thicker line is a different picture"
        assert same(line(1).axes[0], line(1).axes[0]), "an Axes is compared by its figure"
        assert not same(line(1), [0, 1, 3])
    finally:
        plt.close("all")


@pytest.mark.slow
def test_a_mutant_that_never_ends_is_too_slow_and_counts_as_killed(tmp_path: Path) -> None:
    folder = write_total(tmp_path, {"test_s.py": STRONG}, solution=WHILE)
    run = run_mutants(load_assignment(folder), tmp_path / "work", jobs=2)
    assert run.cpu_budget == TIME_FLOOR  # ten times a tiny reference is less than the floor
    endless = [o for o in run.outcomes if "-        i += 1\n+        i = 1\n" in o.mutant.diff]
    assert len(endless) == 1 and endless[0].too_slow and endless[0].killed_by
    assert not any(o.too_slow for o in run.outcomes if o is not endless[0])
    assert run.survivors == () and "TOO SLOW" in format_mutants(run)


@pytest.mark.slow
def test_validate_hull_mutants_prints_its_kill_table_and_passes_the_bar(tmp_path: Path) -> None:
    """The issue's "done when": the real CLI on the shipped hull assignment, its 40 mutants
    (``[mutants] max``) and its ``min_kill_rate`` (0.9); about a minute on two cores."""
    out = tmp_path / "report"
    proc = subprocess.run([sys.executable, "-m", "autograder", "validate",
                           str(ROOT / "assignments" / "hull"), "--mutants", "--jobs", "2",
                           "--out", str(out)],
                          capture_output=True, text=True, timeout=900, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "Mutation analysis of hull (40 of " in proc.stdout
    assert "(minimum 90%)" in proc.stdout and "hull: every example is in its band" in proc.stdout
    data = json.loads((out / "mutants.json").read_text())
    assert data["ok"] and data["min_kill_rate"] == 0.9 and data["kill_rate"] >= 0.9
    assert len(data["mutants"]) == 40
    rows = [line.split()[0] for line in proc.stdout.splitlines()
            if line.startswith(("  orientation-", "  convex_hull-"))]
    assert sorted(rows) == sorted(m["id"] for m in data["mutants"])  # one table row per mutant
    for m in data["mutants"]:  # a survivor needs a check that kills it or a reason
        assert m["equivalent"] or m["killed_by"] or m["accepted"], (
            f"{m['id']} survives and assignments/hull/mutants.toml gives no reason:\n{m['diff']}")
