"""Tests written as notebook cells (nbgrader's autograder cells, otter's test cases).

A course that comes from nbgrader or otter keeps its tests in the notebook rather
than in pytest files. Each such test is one :class:`CellTest`: code that runs in
the student's sandboxed process, in place of a locked cell of the student's
notebook (or after its last cell), and earns its points when it runs without
raising. This module places the tests among the student's cells
(:func:`place_cell_tests`) and scores them on the trusted side from the worker's
plain reports (:func:`score_cell_tests`), as nbgrader scores them:

* full points when the cell raises no error and writes nothing to stderr;
* zero when it raises or writes to stderr (nbgrader's rule);
* nbgrader's partial credit when the cell's last expression is a number between
  0 and the points (any other value: full points, as nbgrader).

The test runs inside the student's process, so a hostile student can subvert it
(see docs/security.md); what this module guarantees is that nothing of a hidden
test (source, printed output, error) reaches the student's feedback.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Sequence

from autograder.results.model import CheckResult

__all__ = ["CellTest", "CellReport", "ManualCell", "manual_result", "PlacedTests", "place_cell_tests", "score_cell_tests",
           "PARTIAL_CREDIT", "STDERR_WRITTEN", "WITHHELD", "withhold_after_hidden"]

#: ``ename`` the wrapper raises to report a number as the cell's result (partial credit)
PARTIAL_CREDIT = "NumgradePartialCredit"
#: ``ename`` the wrapper raises when a test cell wrote to stderr (nbgrader: no credit)
STDERR_WRITTEN = "NumgradeStderrWritten"
#: the one note said for everything held back by :func:`withhold_after_hidden`
WITHHELD = ("The output of cells run after a hidden test is not shown (printed text, "
            "displays, error messages): code that ran before could have read the hidden test.")


@dataclass(frozen=True)
class CellTest:
    """One test cell of an assignment.

    Attributes
    ----------
    name : str
        What the feedback calls it (nbgrader: the cell's ``grade_id``; otter: the
        question and the case number, ``"q1 - 2"``).
    notebook : str
        File name of the assignment notebook the test belongs to.
    points : float
        Points earned when the code runs without raising.
    source : str
        The code the worker runs, hidden parts included. Never sent to a student.
    hidden : bool
        True when nothing of the source or the output may reach the student.
    grade_id : str or None
        nbgrader: the ``grade_id`` of the locked cell whose place the test takes in
        the student's notebook. None: the test runs after the notebook's last cell.
    """

    name: str
    notebook: str
    points: float
    source: str
    hidden: bool = False
    grade_id: str | None = None


@dataclass(frozen=True)
class ManualCell:
    """A cell a person grades (nbgrader: ``grade`` and ``solution``, or a task cell).

    It is listed in every result with its points, as waiting for a person, so a
    score is never silently out of fewer points than the assignment gives.
    """

    name: str
    notebook: str
    points: float
    kind: str = "answer"  # answer | task


def manual_result(cell: ManualCell) -> CheckResult:
    """The result of a manually graded cell before a person has graded it."""
    what = "task" if cell.kind == "task" else "answer"
    return CheckResult(name=cell.name, score=0.0, max_score=cell.points, hidden=False,
                       kind="needs-person",
                       output=f"This {what} is graded by a person ({cell.points:g} point(s)); "
                              "its points are not counted yet.")


def unanswered_result(cell: ManualCell) -> CheckResult:
    """The result of an answer cell a person grades that the student left as released:
    0 points, as nbgrader gives it, and no person needed."""
    return CheckResult(name=cell.name, score=0.0, max_score=cell.points, hidden=False,
                       kind="missing",
                       output=f"No response: this answer is as it was released, so it gets 0 of "
                              f"{cell.points:g} point(s) without waiting for a person.")


# Written by hand: nbgrader runs test cells as plain kernel cells and reads their
# outputs from the executed notebook; our worker reports only how a cell ended, so
# this wrapper turns nbgrader's output rules (stderr, a number as the result) into
# how the cell ends, and keeps a hidden test's output out of the notebook's output.
_RUNNER = '''
def run(source, hidden, namespace):
    import ast, contextlib, io, sys
    class NumgradePartialCredit(Exception):
        pass
    class NumgradeStderrWritten(Exception):
        pass
    shell = namespace.get("get_ipython", lambda: None)()
    text = shell.transform_cell(source) if shell is not None else source
    tree = ast.parse(text, "<test cell>")
    last = None
    if tree.body and isinstance(tree.body[-1], ast.Expr):
        last = ast.Expression(tree.body.pop().value)
    out, err, value = io.StringIO(), io.StringIO(), None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            exec(compile(tree, "<test cell>", "exec"), namespace)
            if last is not None:
                value = eval(compile(last, "<test cell>", "eval"), namespace)
    finally:
        if not hidden:
            sys.stdout.write(out.getvalue())
            sys.stdout.write(err.getvalue())
    if err.getvalue():
        raise NumgradeStderrWritten("the test cell wrote to stderr")
    if value is not None:
        try:
            number = float(repr(value))
        except (TypeError, ValueError):
            return
        raise NumgradePartialCredit(repr(number))
'''


def wrapped_source(test: CellTest) -> str:
    """The cell the worker runs for ``test``: :data:`_RUNNER` applied to its source."""
    return (
        "_numgrade_runner = {}\n"
        f"exec({_RUNNER!r}, _numgrade_runner)\n"
        "try:\n"
        f"    _numgrade_runner['run']({test.source!r}, {test.hidden!r}, globals())\n"
        "finally:\n"
        "    del _numgrade_runner\n")


@dataclass(frozen=True)
class PlacedTests:
    """The cells the worker runs, and which of them are tests.

    Attributes
    ----------
    cells : tuple of (int, str)
        ``(index, source)`` in running order; a test cell keeps the index of the
        student's cell it replaces, a test with no such cell gets an index past
        the notebook's last cell.
    tests : tuple of (int, CellTest)
        The index each test ran under.
    notes : tuple of str
        For the student: tests whose cell was missing from the notebook.
    """

    cells: tuple[tuple[int, str], ...]
    tests: tuple[tuple[int, CellTest], ...]
    notes: tuple[str, ...] = ()

    @property
    def test_indices(self) -> frozenset[int]:
        return frozenset(index for index, _ in self.tests)

    @property
    def hidden_sources(self) -> dict[int, str]:
        """The cells of the hidden tests, by index: the worker gets each only on reaching it."""
        hidden = {index for index, test in self.tests if test.hidden}
        return {index: source for index, source in self.cells if index in hidden}


def place_cell_tests(cells: Sequence[tuple[int, str, str | None]],
                     tests: Sequence[CellTest], *, end: int) -> PlacedTests:
    """Put each test in the place of the student's cell with its ``grade_id``.

    Parameters
    ----------
    cells : sequence of (index, source, grade_id)
        The student's code cells, in order, after locked cells were matched (at
        most one cell carries a given ``grade_id``; see
        :func:`autograder.engine.notebook.restore_locked`).
    tests : sequence of CellTest
        This notebook's tests.
    end : int
        An index past every cell of the notebook (markdown included).

    A test whose cell the student deleted runs after the last cell, and a note
    says so (nbgrader adds a deleted test cell back the same way).
    """
    by_id = {t.grade_id: t for t in tests if t.grade_id is not None}
    placed: list[tuple[int, str]] = []
    ran: list[tuple[int, CellTest]] = []
    for index, source, grade_id in cells:
        test = by_id.pop(grade_id, None) if grade_id is not None else None
        if test is None:
            placed.append((index, source))
        else:
            placed.append((index, wrapped_source(test)))
            ran.append((index, test))
    notes = []
    missing = [t for t in tests if t.grade_id is None or t.grade_id in by_id]
    for offset, test in enumerate(missing):
        placed.append((end + offset, wrapped_source(test)))
        ran.append((end + offset, test))
        if test.grade_id is not None:
            notes.append(f"The test cell `{test.grade_id}` is missing from your notebook; it "
                         "was run after your last cell. Start again from the released "
                         "notebook if you deleted it.")
    return PlacedTests(cells=tuple(placed), tests=tuple(ran), notes=tuple(notes))


@dataclass(frozen=True)
class CellReport:
    """How a cell ended, as far as scoring needs it (from the worker's report)."""

    index: int
    ok: bool
    ename: str = ""
    evalue: str = ""
    traceback: str = ""


def score_cell_tests(placed: PlacedTests, reports: Sequence[CellReport], *,
                     timed_out: Sequence[int] = (), crashed: Sequence[int] = (),
                     section: str = "") -> tuple[CheckResult, ...]:
    """One :class:`CheckResult` per test, from how its cell ended.

    ``section``: put before each test's name (the notebook, when an assignment has
    several). A hidden test's result says only "hidden test passed/failed".
    """
    ended = {r.index: r for r in reports}
    results = []
    for index, test in placed.tests:
        report = ended.get(index)
        if index in timed_out:
            score, kind, why = 0.0, "timeout", "the test cell did not finish within the time limit"
        elif index in crashed:
            score, kind, why = 0.0, "crashed", "the test cell stopped the worker"
        elif report is None:
            score, kind, why = 0.0, "not-run", "the test cell did not run (the worker stopped before it)"
        else:
            score, kind, why = _verdict(report, test)
        name = f"{section}: {test.name}" if section else test.name
        if test.hidden:
            why = "Hidden test passed." if kind == "ok" else (
                "Hidden test failed." if kind not in ("timeout", "crashed", "not-run")
                else f"Hidden test failed: {why}.")
        results.append(CheckResult(name=name, score=score, max_score=test.points,
                                   output=why, hidden=test.hidden, kind=kind))
    return tuple(results)


def _verdict(report: CellReport, test: CellTest) -> tuple[float, str, str]:
    if report.ok:
        return test.points, "ok", ""
    if report.ename == PARTIAL_CREDIT:
        try:
            number = float(report.evalue)
        except ValueError:
            number = -1.0
        if 0.0 <= number <= test.points:
            kind = "ok" if number == test.points else "partial"
            return number, kind, f"The test cell gave {number:g} of {test.points:g} point(s)."
        return test.points, "ok", ""  # nbgrader: a result it cannot use gives full points
    if report.ename == STDERR_WRITTEN:
        return 0.0, "exception", "The test cell wrote to stderr (a warning or an error message)."
    message = f"{report.ename}: {report.evalue}".strip(": ")
    if report.traceback:
        message += "\n\n" + report.traceback
    return 0.0, "exception", message


def withhold_after_hidden(placed: PlacedTests, results: Sequence[CheckResult],
                          hidden_from: int | None) -> tuple[CheckResult, ...]:
    """``results`` (from :func:`score_cell_tests`, same order) with the error text of the
    visible tests that ran from the cell ``hidden_from`` on replaced by :data:`WITHHELD`.

    Student code may have read a hidden test by then and can write what it read into
    a later test's error. Scores stay; hidden tests already say only passed/failed.
    """
    if hidden_from is None:
        return tuple(results)
    kept = []
    for (index, test), result in zip(placed.tests, results):
        if index >= hidden_from and not test.hidden and result.kind == "exception":
            result = replace(result, output=WITHHELD)
        kept.append(result)
    return tuple(kept)
