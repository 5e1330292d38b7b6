"""Grade an assignment's mutants and say which checks kill which (``validate --mutants``).

Every mutant (:mod:`autograder.authoring.mutants`) is a submission like any
other: the instructor notebook with one function changed, graded with the
engine in one batch (sandboxed, ``--jobs`` in parallel), next to the
unchanged notebook. A check *kills* a mutant when it gives it fewer points
than full; a check that already loses points on the unchanged notebook kills
nothing (it is reported as a problem).

Equivalent mutants: a mutant no check kills is graded once more as a *probe*:
its notebook gets one more cell that keeps the model solution's functions
(renamed ``_ngref_*``) and wraps each function the checks call so that every
call runs the reference and the mutant on the same arguments (functions passed
in are memoised, so the reference's calls to them are not counted twice) and
raises when the outputs are not identical (same types, shapes, dtypes and
values, NaN equal to NaN; a matplotlib figure by the pixels it draws) or when
only one of them raises. A probe that still gets full points gave the checks
the reference's very outputs on every input they tried: the mutant is
*equivalent* on the checks' data, reported apart and not counted in the kill
rate. A probe that loses points is an ordinary survivor: its outputs differ and
no check noticed.

Time: the reference is graded first, alone; each mutant then gets a CPU budget of
:data:`TIME_FACTOR` times the reference's CPU seconds (at least :data:`TIME_FLOOR`,
never more than the assignment's own limits) for its notebook and every call. A
mutant that spends it (a fault that makes the code loop or slow down a hundredfold:
a float filter that sends every case to exact arithmetic, a retry that never
succeeds) is reported as *too slow* and counted as killed, as mutmut and PIT count
their timeouts; graded to the assignment's full limits, each such mutant cost
minutes. Probes, which run the reference and the mutant, get twice the budget.
"""

from __future__ import annotations

import random
import re
import time
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import nbformat

from autograder.authoring.mutants import (REF_PREFIX, Mutant, generate_mutants, graded_functions,
                                          reference_copies)
from autograder.engine.assignment import Assignment
from autograder.engine.grader import GradingOptions, budgets
from autograder.engine.slot import GradingSlot
from autograder.errors import AssignmentError
from autograder.results.model import SubmissionResult
from autograder.runners.batch import grade_batch

__all__ = ["MutantOutcome", "MutationRun", "run_mutants", "mutation_settings"]

#: mutants graded per assignment unless ``[mutants] max`` says otherwise
DEFAULT_MAX = 40
#: a mutant's CPU budget: this many times the reference's CPU seconds ...
TIME_FACTOR = 10.0
#: ... but at least this many seconds (a fast reference's few seconds of CPU vary)
TIME_FLOOR = 10.0
REFERENCE = "reference"

#: the probe cell (see the module docstring); ``{wraps}`` rebinds each checked function
PROBE = '''
import copy as _ng_copy
import io as _ng_io
import numpy as _ng_np

class _NgDiffers(Exception):
    """The mutant's output differs from the model solution's."""

def _ng_pixels(obj):
    """A matplotlib Figure (or Axes) as the picture it draws; None for anything else."""
    fig = obj if hasattr(obj, "savefig") else getattr(obj, "figure", None)
    if not hasattr(fig, "savefig"):
        return None
    buffer = _ng_io.BytesIO()
    fig.savefig(buffer, format="rgba")
    return tuple(fig.get_size_inches()), fig.dpi, buffer.getvalue()

def _ng_same(a, b):
    if callable(a) or callable(b):
        return callable(a) and callable(b)
    if type(a) is not type(b):
        return False
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_ng_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_ng_same(a[k], b[k]) for k in a)
    if not isinstance(a, (_ng_np.ndarray, _ng_np.generic, int, float, complex, str, bytes)):
        pictures = _ng_pixels(a)
        if pictures is not None:
            return pictures == _ng_pixels(b)
    x, y = _ng_np.asarray(a), _ng_np.asarray(b)
    if x.dtype != y.dtype or x.shape != y.shape:
        return False
    if x.dtype.kind in "fc":
        return bool(_ng_np.array_equal(x, y, equal_nan=True))
    return bool(_ng_np.array_equal(x, y))

def _ng_memo(f):
    if not callable(f):
        return f
    seen = {}
    def memo(*args):
        try:
            key = tuple((_ng_np.asarray(a).dtype.str, _ng_np.asarray(a).shape,
                         _ng_np.asarray(a).tobytes()) for a in args)
        except Exception:
            return f(*args)
        if key not in seen:
            seen[key] = f(*args)
        return _ng_copy.deepcopy(seen[key])
    return memo

def _ng_wrap(mutant, reference):
    def both(*args, **kwargs):
        args = tuple(_ng_memo(a) for a in args)
        kwargs = {k: _ng_memo(v) for k, v in kwargs.items()}
        try:
            want = reference(*_ng_copy.deepcopy(args), **_ng_copy.deepcopy(kwargs))
        except Exception as exc:
            want = exc
        try:
            got = mutant(*args, **kwargs)
        except Exception as exc:
            if isinstance(want, Exception) and type(want) is type(exc):
                raise
            raise _NgDiffers("only the mutant raised") from None
        if isinstance(want, Exception) or not _ng_same(got, want):
            raise _NgDiffers("the outputs differ")
        if callable(got):
            return _ng_wrap(got, want)
        return got
    both.__name__ = getattr(mutant, "__name__", "wrapped")
    both.__doc__ = getattr(mutant, "__doc__", None)
    return both

{wraps}
'''


@dataclass(frozen=True)
class MutantOutcome:
    """One mutant after grading."""

    mutant: Mutant
    score: float
    max_score: float
    killed_by: tuple[str, ...]
    equivalent: bool
    accepted: str | None = None  # the reason given in mutants.toml
    error: str | None = None
    too_slow: bool = False  # spent its whole CPU budget (counted as killed)

    def to_dict(self) -> dict[str, Any]:
        m = self.mutant
        return {"id": m.id, "function": m.function, "operator": m.operator, "line": m.line,
                "diff": m.diff, "equivalent": self.equivalent, "killed_by": list(self.killed_by),
                "score": self.score, "max_score": self.max_score,
                "accepted": self.accepted, "error": self.error, "too_slow": self.too_slow}


@dataclass(frozen=True)
class MutationRun:
    """What the mutation analysis of one assignment found."""

    assignment: str
    outcomes: tuple[MutantOutcome, ...]
    checks: tuple[str, ...]  # every check graded on the reference
    min_kill_rate: float | None
    generated: int  # mutants before the ``max`` draw
    seconds: float
    problems: tuple[str, ...] = ()
    cpu_budget: float = 0.0  # each mutant's CPU seconds (see the module docstring)

    @property
    def counted(self) -> tuple[MutantOutcome, ...]:
        return tuple(o for o in self.outcomes if not o.equivalent)

    @property
    def survivors(self) -> tuple[MutantOutcome, ...]:
        return tuple(o for o in self.counted if not o.killed_by)

    @property
    def kill_rate(self) -> float:
        counted = self.counted
        return (len(counted) - len(self.survivors)) / len(counted) if counted else 1.0

    @property
    def idle_checks(self) -> tuple[str, ...]:
        """Checks that kill no mutant."""
        used = {name for o in self.outcomes for name in o.killed_by}
        return tuple(c for c in self.checks if c not in used)

    @property
    def ok(self) -> bool:
        low = self.min_kill_rate
        return not self.problems and (low is None or self.kill_rate >= low - 1e-12)

    def to_dict(self) -> dict[str, Any]:
        return {"assignment": self.assignment, "kill_rate": self.kill_rate,
                "min_kill_rate": self.min_kill_rate, "ok": self.ok,
                "generated": self.generated, "graded": len(self.outcomes),
                "equivalent": sum(o.equivalent for o in self.outcomes),
                "survivors": [o.mutant.id for o in self.survivors],
                "idle_checks": list(self.idle_checks), "seconds": self.seconds,
                "cpu_budget": self.cpu_budget,
                "problems": list(self.problems),
                "mutants": [o.to_dict() for o in self.outcomes]}


def mutation_settings(assignment: Assignment) -> tuple[float | None, int, dict[str, str]]:
    """``[mutants]`` of assignment.toml (``min_kill_rate``, ``max``) and the accepted
    survivors of ``mutants.toml`` (``[[accepted]] id = ..., reason = ...``)."""
    toml_path = assignment.root / "assignment.toml"
    config = tomllib.loads(toml_path.read_text("utf-8")) if toml_path.is_file() else {}
    section = config.get("mutants", {})
    rate, most = section.get("min_kill_rate"), section.get("max", DEFAULT_MAX)
    if rate is not None and not (isinstance(rate, (int, float)) and 0 <= rate <= 1):
        raise AssignmentError(f"{toml_path}: [mutants] min_kill_rate must be a number between "
                              f"0 and 1 (e.g. 0.9); got {rate!r}.")
    if not (isinstance(most, int) and most >= 1):
        raise AssignmentError(f"{toml_path}: [mutants] max must be a whole number >= 1 "
                              f"(mutants graded); got {most!r}.")
    accepted: dict[str, str] = {}
    listed = assignment.root / "mutants.toml"
    if listed.is_file():
        for entry in tomllib.loads(listed.read_text("utf-8")).get("accepted", []):
            if not (isinstance(entry, dict) and isinstance(entry.get("id"), str)
                    and isinstance(entry.get("reason"), str) and entry["reason"].strip()):
                raise AssignmentError(f"{listed}: each [[accepted]] needs an id and a reason "
                                      f"(why the checks may let this mutant live); got {entry!r}.")
            accepted[entry["id"]] = entry["reason"]
    return (None if rate is None else float(rate)), most, accepted


def checked_functions(assignment: Assignment, names: set[str]) -> set[str]:
    """The solution functions whose names appear in a check file (the ones the checks call)."""
    text = "\n".join(p.read_text("utf-8", errors="replace")
                     for p in (*assignment.public_checks, *assignment.hidden_checks)
                     if p.suffix == ".py")
    return {n for n in names if re.search(rf"\b{re.escape(n)}\b", text)}


def draw(mutants: list[Mutant], limit: int, seed: str) -> list[Mutant]:
    """``limit`` of ``mutants``, drawn by a generator seeded by ``seed`` (the same every
    time), kept in source order."""
    if len(mutants) <= limit:
        return mutants
    keep = set(random.Random(f"mutants:{seed}").sample(range(len(mutants)), limit))
    return [m for i, m in enumerate(mutants) if i in keep]


def _write(notebook: nbformat.NotebookNode, cell: int, source: str, path: Path,
           probe: str | None = None) -> None:
    copy = nbformat.from_dict(notebook)
    copy.cells[cell].source = source
    if probe is not None:
        copy.cells.append(nbformat.v4.new_code_cell(probe))
    nbformat.write(copy, path)


def _killers(result: SubmissionResult | None, broken: set[str]) -> tuple[str, ...]:
    if result is None:
        return ()
    return tuple(t.name for t in result.tests
                 if t.score < t.max_score - 1e-9 and t.name not in broken)


def time_budget(assignment: Assignment, options: GradingOptions | None,
                reference: SubmissionResult | None, *,
                scale: float = 1.0) -> tuple[float, GradingOptions]:
    """A mutant's CPU budget (see the module docstring) and the options that set it;
    ``scale`` multiplies every limit (a probe runs two solutions)."""
    base = options or GradingOptions()
    notebook_limit, whole = budgets(assignment, base)
    call_limit = base.call_timeout or assignment.call_timeout
    spent = reference.cpu_seconds if reference is not None else whole
    budget = min(whole, max(TIME_FLOOR, TIME_FACTOR * spent))
    return budget, replace(base, cpu_budget=scale * budget,
                           notebook_timeout=scale * min(notebook_limit, budget),
                           call_timeout=scale * min(call_limit, budget))


def _grade(assignment: Assignment, folder: Path, out: Path, jobs: int | None,
           options: GradingOptions | None, slot: GradingSlot | None) -> dict[str, SubmissionResult]:
    report = grade_batch(assignment, [folder], out, jobs=jobs, options=options,
                         progress=False, started_slot=slot)
    return {r.id: r for r in report.results}


def run_mutants(assignment: Assignment, work: Path, *, jobs: int | None = None,
                options: GradingOptions | None = None, max_mutants: int | None = None,
                started_slot: GradingSlot | None = None) -> MutationRun:
    """Generate, grade and classify the mutants of ``assignment`` (in ``work``)."""
    start = time.perf_counter()
    rate, most, accepted = mutation_settings(assignment)
    notebook = nbformat.read(str(assignment.notebook), as_version=4)
    every = generate_mutants(notebook)
    called = checked_functions(assignment, {m.function for m in every})
    graded = graded_functions(notebook, called)
    chosen = [m for m in every if m.function in graded]
    mutants = draw(chosen, max_mutants or most, assignment.name)
    first = work / "reference"
    first.mkdir(parents=True, exist_ok=True)
    nbformat.write(notebook, first / f"{REFERENCE}.ipynb")
    ref = _grade(assignment, first, work / "reference-result", 1, options,
                 started_slot).get(REFERENCE)
    budget, limited = time_budget(assignment, options, ref)
    folder = work / "mutants"
    folder.mkdir(parents=True, exist_ok=True)
    for m in mutants:
        _write(notebook, m.cell, m.cell_source, folder / f"{m.id}.ipynb")
    results = _grade(assignment, folder, work / "mutant-results", jobs, limited, None)
    problems = []
    broken = {t.name for t in ref.tests if t.score < t.max_score - 1e-9} if ref else set()
    if ref is None or ref.outcome == "error":
        problems.append("the unchanged instructor notebook could not be graded")
    problems += [f"check {name} loses points on the unchanged model solution: it can kill "
                 "nothing until it passes there" for name in sorted(broken)]
    alive = [m for m in mutants if not _killers(results.get(m.id), broken)]
    probes = _probe(assignment, notebook, alive, called, work, jobs,
                    time_budget(assignment, options, ref, scale=2)[1])
    outcomes = []
    for m in mutants:
        r = results.get(m.id)
        killed = _killers(r, broken)
        slow = r is not None and r.cpu_seconds >= 0.99 * budget
        probe = probes.get(m.id)
        equivalent = not killed and probe is not None and probe.max_score > 0 \
            and probe.score >= probe.max_score - 1e-9
        outcomes.append(MutantOutcome(
            m, r.score if r else 0.0, r.max_score if r else 0.0, killed, equivalent,
            accepted.get(m.id) if not killed and not equivalent else None,
            None if r is None or r.outcome != "error" else r.output[:300], slow))
    checks = tuple(t.name for t in ref.tests) if ref else ()
    return MutationRun(assignment.name, tuple(outcomes), checks, rate, len(chosen),
                       time.perf_counter() - start, tuple(problems), budget)


def _probe(assignment: Assignment, notebook: nbformat.NotebookNode, alive: list[Mutant],
           called: set[str], work: Path, jobs: int | None,
           options: GradingOptions | None) -> dict[str, SubmissionResult]:
    if not alive:
        return {}
    wraps = "\n".join(f"{name} = _ng_wrap({name}, {REF_PREFIX}{name})" for name in sorted(called))
    cell = reference_copies(notebook) + "\n\n" + PROBE.replace("{wraps}", wraps)
    folder = work / "probes"
    folder.mkdir(parents=True, exist_ok=True)
    for m in alive:
        _write(notebook, m.cell, m.cell_source, folder / f"{m.id}.ipynb", probe=cell)
    return _grade(assignment, folder, work / "probe-results", jobs, options, None)
