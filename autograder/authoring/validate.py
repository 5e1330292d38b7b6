"""``autograder validate ASSIGNMENT``: the instructor's own CI for an assignment folder.

:func:`validate` does what a course would otherwise find out from students:

1. releases the assignment (:func:`autograder.authoring.release.release`, which refuses
   to write a solution or a hidden check) into a scratch folder;
2. checks the released folder again, file by file: no nbgrader solution or
   hidden-test marker, no distinctive line of a solution region or of a hidden
   check, no copy of a hidden check file;
3. grades every ``examples/*.ipynb`` and the released template with the same
   engine as ``autograder grade`` (:func:`autograder.runners.batch.grade_batch`);
4. compares each score with its band in ``examples/expected.toml``
   (``[stem] min = ..., max = ..., contains = [...]``; ``[template]`` is the
   released notebook) and reports one row per example.

The report says ``ok`` only when nothing leaked, every example has a band and
lands in it, and no grading ended in a grader error.
"""

from __future__ import annotations

import shutil
import tempfile
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import nbformat

from autograder.authoring.mutants_run import MutationRun, run_mutants
from autograder.authoring.release import FORBIDDEN_MARKERS, release
from autograder.engine.assignment import Assignment
from autograder.engine.grader import GradingOptions
from autograder.engine.slot import GradingSlot
from autograder.errors import AssignmentError
from autograder.results.model import SubmissionResult
from autograder.runners.batch import grade_batch

__all__ = ["ExampleCheck", "ValidationRun", "validate", "format_report"]

#: lines shorter than this (stripped) are too common to count as a leak
DISTINCTIVE = 24
#: the name the released notebook is graded under
TEMPLATE = "template"


@dataclass(frozen=True)
class ExampleCheck:
    """One example's score against its band."""

    name: str
    score: float
    max_score: float
    low: float | None
    high: float | None
    outcome: str
    problems: tuple[str, ...] = ()

    @property
    def fraction(self) -> float:
        return self.score / self.max_score if self.max_score else 0.0

    @property
    def ok(self) -> bool:
        return not self.problems

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "score": self.score, "max_score": self.max_score,
                "fraction": self.fraction, "min": self.low, "max": self.high,
                "outcome": self.outcome, "ok": self.ok, "problems": list(self.problems)}


@dataclass(frozen=True)
class ValidationRun:
    """What :func:`validate` found."""

    assignment: str
    examples: tuple[ExampleCheck, ...]
    leaks: tuple[str, ...] = ()
    problems: tuple[str, ...] = field(default=())
    #: ``validate --mutants``: the mutation analysis (:mod:`autograder.authoring.mutants_run`)
    mutation: MutationRun | None = None

    @property
    def ok(self) -> bool:
        return (not self.leaks and not self.problems and all(e.ok for e in self.examples)
                and (self.mutation is None or self.mutation.ok))

    @property
    def wrongly_failed(self) -> tuple[ExampleCheck, ...]:
        """Examples whose band is full marks (correct variants) but that lose points."""
        return tuple(e for e in self.examples if e.low is not None and e.low >= 1 - 1e-9
                     and e.fraction < 1 - 1e-9)

    def to_dict(self) -> dict[str, Any]:
        return {"assignment": self.assignment, "ok": self.ok, "leaks": list(self.leaks),
                "problems": list(self.problems), "examples": [e.to_dict() for e in self.examples]}


def validate(assignment: Assignment, *, work: Path | None = None, jobs: int | None = None,
             options: GradingOptions | None = None,
             started_slot: GradingSlot | None = None, mutants: bool = False,
             max_mutants: int | None = None) -> ValidationRun:
    """Release ``assignment``, look for leaks, grade its examples and check their bands.

    Parameters
    ----------
    assignment : Assignment
    work : Path, optional
        Folder for the release, the submissions and the results (kept, for
        reading the feedback pages); default: a temporary folder, removed after.
    jobs : int, optional
        Examples graded in parallel (default: the number of cores).
    options : GradingOptions, optional
        As for ``autograder grade``.
    started_slot : GradingSlot, optional
        A slot started ahead (:func:`autograder.engine.slot.start_early`): the first
        local slot; the caller closes it.
    mutants : bool
        Also grade mutants of the model solution and say which checks kill them
        (:func:`autograder.authoring.mutants_run.run_mutants`); ``max_mutants``
        overrides ``[mutants] max``.
    """
    if work is None:
        with tempfile.TemporaryDirectory(prefix=f"validate-{assignment.name}-") as scratch:
            return validate(assignment, work=Path(scratch), jobs=jobs, options=options,
                            started_slot=started_slot, mutants=mutants, max_mutants=max_mutants)
    run = _validate(assignment, Path(work), jobs, options, started_slot)
    if not mutants:
        return run
    mutation = run_mutants(assignment, Path(work), jobs=jobs, options=options,
                           max_mutants=max_mutants)
    return replace(run, mutation=mutation)


def _validate(assignment: Assignment, work: Path, jobs: int | None,
              options: GradingOptions | None, started_slot: GradingSlot | None) -> ValidationRun:
    bands, problems = _read_bands(assignment)
    released = work / "release"
    try:
        template = release(assignment, released)
    except AssignmentError as exc:
        return ValidationRun(assignment.name, (), leaks=(str(exc),), problems=tuple(problems))
    leaks = tuple(find_leaks(assignment, released))
    submissions = work / "submissions"
    submissions.mkdir(parents=True, exist_ok=True)
    examples = sorted((assignment.root / "examples").glob("*.ipynb"))
    for path in examples:
        shutil.copyfile(path, submissions / path.name)
    shutil.copyfile(template, submissions / f"{TEMPLATE}.ipynb")
    report = grade_batch(assignment, [submissions], work / "results", jobs=jobs,
                         options=options, progress=False, started_slot=started_slot)
    results = {r.id: r for r in report.results}
    names = [p.stem for p in examples] + [TEMPLATE]
    for stem in bands:
        if stem not in names:
            problems.append(f"expected.toml has a band for {stem!r}, but there is no "
                            f"examples/{stem}.ipynb")
    checks = tuple(_check_example(stem, results.get(stem), bands.get(stem)) for stem in names)
    return ValidationRun(assignment.name, checks, leaks=leaks, problems=tuple(problems))


def _read_bands(assignment: Assignment) -> tuple[dict[str, dict[str, Any]], list[str]]:
    path = assignment.root / "examples" / "expected.toml"
    if not path.is_file():
        return {}, [f"{path} is missing: give each example a band, e.g. [solution] min = 1, max = 1"]
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        return {}, [f"{path} is not valid TOML: {exc}"]
    bands: dict[str, dict[str, Any]] = {}
    problems = []
    for stem, band in data.items():
        low, high = (band.get("min"), band.get("max")) if isinstance(band, dict) else (None, None)
        if not all(isinstance(v, (int, float)) and 0 <= v <= 1 for v in (low, high)) \
                or low > high:  # type: ignore[operator]
            problems.append(f"{path}: [{stem}] needs min and max between 0 and 1, min <= max")
            continue
        words = band.get("contains", [])
        if not isinstance(words, list) or not all(isinstance(w, str) for w in words):
            problems.append(f"{path}: [{stem}] contains must be a list of strings")
            continue
        bands[stem] = {"min": float(low), "max": float(high), "contains": words}
    return bands, problems


def _check_example(stem: str, result: SubmissionResult | None,
                   band: dict[str, Any] | None) -> ExampleCheck:
    if result is None:
        return ExampleCheck(stem, 0.0, 0.0, None, None, "missing",
                            ("it was not graded (see the grader's messages above)",))
    low = band["min"] if band else None
    high = band["max"] if band else None
    check = ExampleCheck(stem, result.score, result.max_score, low, high, result.outcome)
    problems = []
    if result.outcome == "error":
        problems.append(f"the grader failed: {result.output[:300]}")
    if band is None:
        problems.append("no band in examples/expected.toml: add "
                        f"[{stem}] min = {check.fraction:.2f}, max = {check.fraction:.2f}")
    elif not low - 1e-9 <= check.fraction <= high + 1e-9:
        failed = [f"{t.name} ({t.score:g}/{t.max_score:g})" for t in result.tests
                  if t.status != "passed"][:6]
        problems.append(f"scored {check.fraction:.3f}, outside [{low:g}, {high:g}]; "
                        f"checks not passed: {', '.join(failed) or 'none'}")
    if band is not None:
        text = result.output + "".join(t.output for t in result.tests)
        problems += [f"its feedback never says {word!r}" for word in band["contains"]
                     if word not in text]
    return ExampleCheck(stem, result.score, result.max_score, low, high, result.outcome,
                        tuple(problems))


# -- leaks -----------------------------------------------------------------------

def find_leaks(assignment: Assignment, released: Path) -> list[str]:
    """Every sign that a solution or a hidden check reached the released folder."""
    hidden_files = _files(assignment.root / "checks" / "hidden")
    secret_lines = _solution_lines(assignment.notebook) | _long_lines(hidden_files)
    secret_lines -= _long_lines(_files(assignment.root / "checks" / "public"))
    hidden_bytes = {p.read_bytes(): p for p in hidden_files if p.read_bytes().strip()}
    hidden_names = {p.name for p in hidden_files if p.suffix == ".py"}
    leaks = []
    for path in _files(released):
        where = path.relative_to(released)
        data = path.read_bytes()
        if data in hidden_bytes:
            leaks.append(f"{where} is a copy of the hidden check "
                         f"{hidden_bytes[data].relative_to(assignment.root)}")
            continue
        if path.name in hidden_names:
            leaks.append(f"{where} has the name of a hidden check")
        text = data.decode("utf-8", errors="replace")
        leaks += [f"{where} contains {marker!r}" for marker in FORBIDDEN_MARKERS if marker in text]
        released_text = _released_text(path, text)
        found = sorted(line for line in secret_lines if line in released_text)
        leaks += [f"{where} contains a solution or hidden-check line: {line!r}"
                  for line in found[:5]]
    return leaks


def _files(folder: Path) -> list[Path]:
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts
                  and p.suffix != ".pyc")


def _distinctive(line: str) -> str | None:
    line = line.strip()
    if len(line) < DISTINCTIVE or line.startswith(("#", "import ", "from ")):
        return None
    return line


def _long_lines(paths: list[Path]) -> set[str]:
    lines = set()
    for path in paths:
        if path.suffix == ".py":
            text = path.read_text(encoding="utf-8", errors="replace")
            lines |= {d for d in map(_distinctive, text.splitlines()) if d}
    return lines


def _solution_lines(notebook: Path) -> set[str]:
    """Distinctive lines inside ### BEGIN/END SOLUTION regions that appear nowhere else."""
    inside, outside = set(), set()
    nb = nbformat.read(str(notebook), as_version=4)
    for cell in nb.cells:
        region = False
        for raw in cell.get("source", "").splitlines():
            if "BEGIN SOLUTION" in raw:
                region = True
            elif "END SOLUTION" in raw:
                region = False
            elif (line := _distinctive(raw)) is not None:
                (inside if region else outside).add(line)
    return inside - outside


def _released_text(path: Path, text: str) -> str:
    """What a reader of ``path`` sees: a notebook's cell sources, any other file as it is
    (secret lines are searched as substrings, so a line pasted into a sentence counts)."""
    if path.suffix == ".ipynb":
        try:
            nb = nbformat.reads(text, as_version=4)
        except Exception:  # nbformat raises many types; the raw text is scanned instead
            return text
        return "\n".join(cell.get("source", "") for cell in nb.cells)
    return text


# -- the table ---------------------------------------------------------------------

def format_report(report: ValidationRun) -> str:
    """The table ``autograder validate`` prints, then what is wrong, if anything."""
    lines = [f"Validating {report.assignment}:", "",
             f"  {'example':<28} {'score':>12} {'fraction':>9} {'band':>13}  result"]
    for e in report.examples:
        band = "none" if e.low is None else f"[{e.low:g}, {e.high:g}]"
        score = f"{e.score:g}/{e.max_score:g}"
        lines.append(f"  {e.name:<28} {score:>12} {e.fraction:>9.3f} {band:>13}  "
                     f"{'ok' if e.ok else 'FAIL'}")
        lines += [f"      - {p}" for p in e.problems]
    lines.append("")
    if report.leaks:
        lines.append("Leaks in the released folder:")
        lines += [f"  - {leak}" for leak in report.leaks]
    if report.problems:
        lines.append("Problems:")
        lines += [f"  - {problem}" for problem in report.problems]
    for e in report.wrongly_failed:
        lines.append(f"Correct variant {e.name} (band: full marks) loses points: a check "
                     "wrongly fails it (see its row above).")
    if report.mutation is not None:
        from autograder.authoring.mutants_report import format_mutants

        lines += ["", format_mutants(report.mutation), ""]
    lines.append(f"{report.assignment}: " + (
        "every example is in its band and nothing leaked." if report.ok else
        "NOT valid; fix the rows marked FAIL and the lines above."))
    return "\n".join(lines)
