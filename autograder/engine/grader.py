"""Grade one submission: the unit of work (one notebook in, one result out).

:class:`Grader` keeps a grading slot and the imported checks between
submissions, so a batch engine (ours in :mod:`autograder.runners.batch`, or a
distributed one later) only has to call :meth:`Grader.grade` per file.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.util
import os
import socket
import stat
import tempfile
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

import autograder
from autograder.engine.assignment import Assignment
from autograder.engine.checkrun import CheckSuite, forget_check_modules
from autograder.engine.forbidden import (
    forbidden_functions,
    forbidden_module_paths,
    review_notes,
    scan_sources,
    warm_up,
)
from autograder.engine.celltests import (
    CellReport,
    CellTest,
    PlacedTests,
    WITHHELD,
    manual_result,
    place_cell_tests,
    score_cell_tests,
    unanswered_result,
    withhold_after_hidden,
)
from autograder.engine.identify import identify, released_answers, unanswered
from autograder.engine.notebook import Notebook, locked_cells, read_notebook, restore_locked
from autograder.engine.plugin import CheckContext
from autograder.engine.slot import GradingSlot
from autograder.engine.otter_format import checker_tests, is_otter_notebook, read_otter
from autograder.engine.requirements import check_requirements
from autograder.engine.student_process import (
    NotebookRun,
    StudentProcess,
    check_cell_count,
    wall_limit,
)
from autograder.engine.variants import (Variant, VariantSpec, cell_evidence, submitted_values,
                                        travel_evidence)
from autograder.engine.submission import (
    Submission,
    file_sha256,
    open_submission,
    submission_sha256,
)
from autograder.errors import NotebookError, WorkerCrashed
from autograder.results.model import SUBMISSION_NOTE, CellError, CheckResult, SubmissionResult
from autograder.results.store import write_submission
from autograder.sandbox import affinity
from autograder.sandbox.policy import IsolationPolicy

#: bump when a change to the engine can change a score (part of every result's key)
ENGINE_VERSION = f"autograder-{autograder.__version__}"


@dataclass(frozen=True)
class GradingOptions:
    """How to grade; every field has a safe default (all isolation on)."""

    policy: IsolationPolicy = field(default_factory=IsolationPolicy)
    notebook_timeout: float | None = None
    call_timeout: float | None = None
    public_only: bool = False
    #: a notebook full of outputs is still graded (outputs are dropped on reading)
    max_notebook_bytes: int = 64 * 1024 * 1024

    #: CPU seconds one submission may use in all (notebook, restarts, calls);
    #: None: the notebook limit plus 20 call limits
    cpu_budget: float | None = None

    def digest(self) -> str:
        """Everything in the options that can change a score, the isolation policy included."""
        return hashlib.sha256(repr((self.public_only, self.notebook_timeout, self.call_timeout,
                                    self.cpu_budget, self.max_notebook_bytes,
                                    self.policy)).encode()).hexdigest()[:16]


def policy_for(assignment: Assignment, options: GradingOptions) -> IsolationPolicy:
    """The options' policy with the assignment's limit overrides applied."""
    overrides: dict[str, Any] = dict(assignment.limits)
    if not overrides:
        return options.policy
    limits = replace(options.policy.limits, **overrides)
    return replace(options.policy, limits=limits)


def submission_key(sha256: str, assignment: Assignment, options: GradingOptions,
                   *, digest: str | None = None) -> str:
    """Identifies a grading: a result is reused only when this key is unchanged.

    It hashes the notebook's bytes, everything in the assignment folder that
    grading reads (``assignment.toml``, the instructor notebook, data, checks;
    not ``examples/``), the sources of the engine and of ``reference``, and the
    options with the whole isolation policy. ``digest``: the assignment's
    :func:`assignment_digest`, when the caller has it already.
    """
    text = "|".join((sha256, digest or assignment_digest(assignment), engine_digest(),
                     ENGINE_VERSION, options.digest(), repr(assignment.limits),
                     _secret_fingerprint(assignment)))
    return hashlib.sha256(text.encode()).hexdigest()


def _secret_fingerprint(assignment: Assignment) -> str:
    """A digest of the variants' course secret: a new secret draws new variants, so it
    must not reuse results graded under the old one (the secret itself stays out)."""
    if assignment.variants is None:
        return ""
    return str(assignment.variants.seed(assignment.name, "\0fingerprint"))


def submission_seed(assignment: Assignment, student: str) -> int:
    """The seed of a submission's unseen data: from the assignment and the student only.

    Never from the file's bytes, so a comment, whitespace or the time of grading
    cannot change the data a submission is graded on.
    """
    text = f"{assignment.name}\0{student}"
    return int(hashlib.sha256(text.encode()).hexdigest()[:8], 16)


#: folders of an assignment that grading never reads
_NOT_GRADED = frozenset({"examples", "__pycache__", ".ipynb_checkpoints", ".pytest_cache", ".git"})


def assignment_digest(assignment: Assignment) -> str:
    """SHA-256 over the files of the assignment folder that grading reads.

    The contents are hashed again whenever a file's size or modification time
    changes, so an edit made while a service or a batch runs is never missed.
    """
    return _cached_tree_digest(assignment.root, _stat_signature(assignment.root, _NOT_GRADED))


def _stat_signature(root: Path, skip: frozenset[str]) -> tuple[tuple[str, int, int], ...]:
    found = []
    for directory, subdirs, files in os.walk(root):
        subdirs[:] = sorted(d for d in subdirs if d not in skip)
        for name in sorted(files):
            info = os.stat(os.path.join(directory, name))
            found.append((os.path.join(directory, name), info.st_size, info.st_mtime_ns))
    return tuple(found)


@functools.lru_cache(maxsize=64)
def _cached_tree_digest(root: Path, signature: tuple[tuple[str, int, int], ...]) -> str:
    return _tree_digest(root, skip=_NOT_GRADED)


@functools.cache
def engine_digest() -> str:
    """SHA-256 over the engine's sources and the ``reference`` package's, if installed."""
    digest = hashlib.sha256()
    roots = [Path(autograder.__file__).resolve().parent]
    spec = importlib.util.find_spec("reference")
    if spec is not None and spec.submodule_search_locations:
        roots += [Path(p).resolve() for p in spec.submodule_search_locations]
    for root in roots:
        digest.update(f"{root.name}:{_tree_digest(root, skip=frozenset({'__pycache__'}))}".encode())
    return digest.hexdigest()


def _tree_digest(root: Path, *, skip: frozenset[str]) -> str:
    digest = hashlib.sha256()
    for directory, subdirs, files in os.walk(root):
        subdirs[:] = sorted(d for d in subdirs if d not in skip and not d.endswith(".egg-info"))
        for name in sorted(files):
            if name.endswith((".pyc", ".pyo")):
                continue
            path = Path(directory, name)
            digest.update(str(path.relative_to(root)).encode() + b"\0")
            digest.update(file_sha256(path).encode())
    return digest.hexdigest()


class _Unreadable:
    """Stands in for a worker when the file could not be run at all."""

    def __init__(self, message: str) -> None:
        self.message = message

    def call(self, name: str, args: Any, kwargs: dict[str, Any], *, timeout: float,
             figures: bool = False) -> tuple[Any, list[Any]]:
        raise WorkerCrashed(self.message)

    def figures(self, *, timeout: float) -> list[Any]:
        raise WorkerCrashed(self.message)


def budgets(assignment: Assignment, options: GradingOptions) -> tuple[float, float]:
    """The notebook's CPU time limit and the whole submission's CPU budget, in seconds."""
    notebook_timeout = options.notebook_timeout or assignment.notebook_timeout
    call_timeout = options.call_timeout or assignment.call_timeout
    return notebook_timeout, options.cpu_budget or notebook_timeout + 20 * call_timeout


def submission_wall_limit(assignment: Assignment, options: GradingOptions) -> float:
    """The most wall-clock seconds one submission's code can hold a grader, for runners that
    watch a grading from outside (the service's lease keepers)."""
    return wall_limit(*budgets(assignment, options))


class Grader:
    """Grades submissions of one assignment, one at a time, on one grading slot."""

    def __init__(self, assignment: Assignment, options: GradingOptions | None = None,
                 *, slot: int = 0, scratch: Path | None = None,
                 started_slot: GradingSlot | None = None) -> None:
        """``started_slot``: a slot whose warm parent was started ahead (see
        :func:`autograder.engine.slot.start_early`), used instead of claiming ``slot``;
        the grader closes it with itself."""
        self.assignment = assignment
        self.options = options or GradingOptions()
        self.policy = policy_for(assignment, self.options)
        self._locked = {nb.name: locked_cells(nb) for nb in assignment.notebooks}
        #: the checks, collected once and run for every submission, and the
        #: assignment digest they were collected at (a new session when it changes)
        self._checks: CheckSuite | None = None
        #: the submission being graded (its folder is hidden from the worker)
        self._source: Path | None = None
        #: the variant of the submission being graded (None: no variants, or not on the roster)
        self._variant: Variant | None = None
        self._checks_digest = ""
        self._requirements_ok = False
        #: public tests for grader.check, when the notebook is otter's (never the hidden ones)
        self._otter = (checker_tests(read_otter(assignment.notebook))
                       if is_otter_notebook(assignment.notebook) else None)
        self._slot = started_slot if started_slot is not None else GradingSlot(slot=slot, scratch=scratch)

    def __enter__(self) -> "Grader":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def prepare(self, *, wait: bool = True) -> None:
        """Start the warm worker and collect the checks now; return once the worker is ready
        (with ``wait=False``: once the checks are collected, the worker still starting).

        The worker imports numpy, scipy and matplotlib in its own process while this
        one collects the checks, so the first submission waits for neither. Optional:
        :meth:`grade` does whatever is left. A failure here (checks that cannot be
        collected, a worker that does not start) is not raised: :meth:`grade` meets it
        again and reports it in each submission's result, as without this call.
        """
        self._slot.start(wait=False)
        try:
            self.collect()
            if wait:
                self._slot.start()
        except Exception:  # see the docstring: grade() reports it with each submission
            pass

    def collect(self) -> None:
        """Collect the checks and import the static scan now, without the worker.

        Raises what collecting raises (:meth:`prepare` leaves that to :meth:`grade`).
        """
        if self.check_files:
            self._check_session(self._context(_Unreadable("no submission yet"), (), {}, 0,
                                              None), assignment_digest(self.assignment))
        warm_up(self.assignment.rules)

    def sibling(self, worker: GradingSlot) -> "Grader":
        """A grader of the same assignment and options on ``worker``'s slot, starting with
        the checks this grader collected; call it in a process forked from this one.

        The pool processes of a ``--jobs N`` batch are forked from the batch's process
        once slot 0 collected its checks (:mod:`autograder.runners.local`): each then
        holds a copy of the collected session of its own, and importing the engine and
        collecting the checks again (about a CPU second per slot) is skipped. This
        process's copy of this grader's slot is closed without touching the owner's
        warm parent or folder (:meth:`GradingSlot.disown`); this grader serves nothing
        after the call.
        """
        self._slot.disown()
        sibling = Grader(self.assignment, self.options, started_slot=worker)
        sibling._checks, sibling._checks_digest = self._checks, self._checks_digest
        self._checks = None  # this process's copy: closed with the sibling only
        return sibling

    def warm_copies(self, count: int) -> list[tuple[int, socket.socket]]:
        """Copies of this grader's warm parent for ``count`` other slots of its batch.

        Call it after :meth:`prepare` and before the first submission; see
        :meth:`autograder.engine.slot.GradingSlot.warm_copies`.
        """
        return self._slot.warm_copies(count, forbid=self.assignment.rules.to_wire())

    def check_requirements(self) -> None:
        """Raise :class:`AssignmentError` unless every requirement imports in the worker.

        Runs once per grader, before its first submission: a ``import`` of each
        required package's modules, in a sandboxed worker like a submission's (see
        :mod:`autograder.engine.requirements`).
        """
        if self.assignment.requirements and not self._requirements_ok:
            check_requirements(self.assignment.requirements, self._run_probe,
                               where=f"The assignment {self.assignment.name!r}")
            self._requirements_ok = True

    def _run_probe(self, cells: list[tuple[int, str]]) -> list[tuple[bool, str]]:
        session = StudentProcess(
            slot=self._slot, cells=cells, data_files=(), policy=self.policy,
            notebook_timeout=self.assignment.notebook_timeout, exclude=self._excluded_paths(),
            forbid=self.assignment.rules.to_wire())
        try:
            run = session.start()
        finally:
            session.close()
        ran = {c.index: c for c in run.cells}
        return [(ran[i].ok, f"{ran[i].ename}: {ran[i].evalue}") if i in ran
                else (False, "the worker stopped before it ran") for i, _ in cells]

    def close(self) -> None:
        try:
            self._close_checks()
        finally:
            self._slot.shutdown()

    def _close_checks(self) -> None:
        checks, self._checks = self._checks, None
        if checks is not None:
            checks.close()

    @property
    def core(self) -> int | None:
        """The core this grader's slot runs on (see :mod:`autograder.sandbox.affinity`)."""
        return self._slot.core

    @property
    def check_files(self) -> list[Path]:
        files = list(self.assignment.public_checks)
        if not self.options.public_only:
            files += list(self.assignment.hidden_checks)
        return files

    # -- the unit of work ----------------------------------------------------
    def grade(self, path: Path, *, id: str | None = None,
              out_dir: Path | None = None) -> SubmissionResult:
        """Grade ``path``; write the result folder ``out_dir`` when it is given.

        ``path`` is the student's notebook, or, for an assignment of several
        notebooks, a folder holding them under the assignment's file names. Each
        notebook runs in its own worker process; the result sums their points.
        Raises :class:`AssignmentError` before grading anything when a package the
        assignment requires does not import in the worker (every runner: the batch,
        the service, Dask, Gradescope).
        """
        self.check_requirements()  # once per grader; a no-op for most assignments
        start = time.perf_counter()
        sub_id = id or Path(path).stem
        raw_sha = submission_sha256(Path(path))
        digest = assignment_digest(self.assignment)
        key = submission_key(raw_sha, self.assignment, self.options, digest=digest)
        seed = submission_seed(self.assignment, sub_id)
        self._source = Path(path)  # its folder holds other submissions: see _excluded_paths
        spec = self.assignment.variants
        self._variant = spec.lookup(self.assignment.name, sub_id) if spec is not None else None
        several = len(self.assignment.notebooks) > 1
        # -- intake: a notebook, folder or zip -> its files (engine/submission.py), and
        # whether the notebook is this assignment's (engine/identify.py)
        with tempfile.TemporaryDirectory(prefix="submission-",
                                         dir=self._slot.intake_root) as scratch:
            submission = open_submission(Path(path), self.assignment.notebooks,
                                         scratch=Path(scratch))
            files = dict(submission.notebooks)
            # the student's parameters cell, read (never run) while the files are here
            cell = (submitted_values(files.get(self.assignment.notebooks[0].name), spec.cell,
                                     max_bytes=self.options.max_notebook_bytes)
                    if spec is not None else None)
            parts = [(nb.name, self._grade_part(
                nb.name, files.get(nb.name), submission, seed, out_dir, digest,
                section=nb.name if several else None)) for nb in self.assignment.notebooks]
        result = _combined(self.assignment.name, parts, seed)
        result = replace(result, notes=submission.notes + result.notes)
        waiting = sum(t.max_score for t in result.tests if t.kind == "needs-person")
        if waiting:
            result = replace(result, output=f"{result.output}\n{waiting:g} point(s) wait for a "
                                            "person to grade them; they are not in the score yet.")
        result = replace(result, id=sub_id, source=str(path), key=key, sha256=raw_sha,
                         execution_time=time.perf_counter() - start, engine=ENGINE_VERSION)
        if spec is not None:
            result = with_variant(result, self.assignment.name, spec, self._variant,
                                  submitted=cell)
        if out_dir is not None:
            write_submission(out_dir, result, title=self.assignment.title,
                             deadline=self.assignment.deadline)
        return result

    def _grade_part(self, name: str, path: Path | None, submission: Submission, seed: int,
                    out_dir: Path | None, digest: str, *, section: str | None) -> SubmissionResult:
        """One notebook of the submission (a whole submission when there is one)."""
        runs_checks = name == self.assignment.notebook.name
        notebook, problem = self._intake(name, path, submission)
        if notebook is not None:
            part = self._grade_notebook(notebook, seed, out_dir, digest, name=name,
                                        runs_checks=runs_checks)
        else:
            part = self._grade_unreadable(problem, seed, out_dir, digest, name=name,
                                          runs_checks=runs_checks)
        return _in_section(part, section)

    def _intake(self, name: str, path: Path | None, submission: Submission
                ) -> tuple[Notebook | None, str]:
        """The student's notebook ``name`` with its locked cells restored, or the problem."""
        if submission.problem:
            return None, submission.problem
        if path is None:
            return None, (f"The notebook {name!r} is missing from your submission; hand in "
                          "every notebook of the assignment under its released name.")
        try:
            _require_regular_file(path)
            notebook = read_notebook(path, max_bytes=self.options.max_notebook_bytes)
            check_cell_count(len(notebook.cells))
        except NotebookError as exc:
            return None, str(exc)
        if name == self.assignment.notebooks[0].name:  # which assignment: from the first
            identity = identify(notebook, self.assignment)
            if identity.problem:
                return None, identity.problem
            notebook = replace(notebook, warnings=notebook.warnings + identity.notes)
        return restore_locked(notebook, self._locked[name]), ""

    def _cell_tests(self, name: str) -> list[CellTest]:
        return [t for t in self.assignment.cell_tests if t.notebook == name]

    def _grade_unreadable(self, problem: str, seed: int, out_dir: Path | None,
                          digest: str, *, name: str, runs_checks: bool) -> SubmissionResult:
        message = f"This file could not be graded: {problem}"
        tests = (self._run_checks(_Unreadable(message), (), {}, seed, out_dir, digest)
                 if runs_checks and self.check_files else ())
        placed = place_cell_tests([], self._cell_tests(name), end=0)
        cell_tests = score_cell_tests(placed, [])
        return _result(self.assignment.name, "ungradable", message,
                       cell_tests + tests + self._manual(name), seed)

    def _manual(self, name: str, student: Path | None = None) -> tuple[CheckResult, ...]:
        cells = [m for m in self.assignment.manual_cells if m.notebook == name]
        empty: set[str] = set()
        if student is not None and any(m.kind == "answer" for m in cells):
            source = next(nb for nb in self.assignment.notebooks if nb.name == name)
            empty = unanswered(student, released_answers(source))
        return tuple(unanswered_result(m) if m.kind == "answer" and m.name in empty
                     else manual_result(m) for m in cells)

    def _grade_notebook(self, notebook: Notebook, seed: int, out_dir: Path | None,
                        digest: str, *, name: str, runs_checks: bool) -> SubmissionResult:
        sources, numbers = [c.source for c in notebook.cells], [c.index for c in notebook.cells]
        placed = place_cell_tests([(c.index, c.source, c.grade_id) for c in notebook.cells],
                                  self._cell_tests(name), end=notebook.end)
        session = self._session(placed, out_dir)
        runs_checks = runs_checks and bool(self.check_files)
        # This thread and the child take turns (a call waits for its answer): on the
        # slot's core, a message does not have to wake another core (autograder.sandbox.affinity).
        # With a warm parent ready, the child is forked first and enters its sandbox
        # while this thread scans the notebook (session.launch). Otherwise (the first
        # submission, or after a crash) the scan and the checks' session come first, off
        # the slot's core, while the warm parent starts and imports its libraries there.
        warm = self._slot.warm
        with affinity.on_core(self._slot.core) if warm else contextlib.nullcontext():
            try:
                if warm:
                    session.launch()
                report = scan_sources(self.assignment.rules, sources)
                forbidden = forbidden_functions(self.assignment.rules, sources, numbers, report)
                self._slot.start(wait=False)
                if runs_checks:
                    self._check_session(self._context(session, (), forbidden, seed, out_dir),
                                        digest)
                with affinity.on_core(self._slot.core):
                    run = session.start()
                    tests = (self._run_checks(session, run.functions, forbidden, seed, out_dir,
                                              digest) if runs_checks else ())
            finally:
                session.close()
        run = session.report or run  # as it stands after the calls (a protocol violation)
        cell_tests = score_cell_tests(
            placed, [CellReport(c.index, c.ok, c.ename, c.evalue, c.traceback) for c in run.cells],
            timed_out=run.timed_out_cells, crashed=run.crashed_cells)
        cell_tests = withhold_after_hidden(placed, cell_tests, run.hidden_from)
        if run.hidden_from is not None:
            tests = withhold_check_output(tests, out_dir)
        # what the student's own cells did: the test cells are reported as checks above
        run = withhold_cell_errors(without_cells(run, placed.test_indices))
        outcome = ("timeout" if run.timed_out_cells else
                   "crashed" if run.crashed or run.crashed_cells else "graded")
        result = _result(self.assignment.name, outcome, summarise_run(run, notebook),
                         cell_tests + tests + self._manual(name, notebook.path), seed)
        return replace(result, stdout=run.stdout,
                       notes=(tuple(run.notes) + tuple(notebook.warnings) + placed.notes
                              + review_notes(report, numbers)
                              + ((WITHHELD,) if run.hidden_from is not None else ())),
                       cpu_seconds=round(session.cpu_seconds, 3),
                       cell_errors=tuple(CellError(c.index, c.ename, c.evalue, c.traceback)
                                         for c in run.cells if not c.ok))

    def _session(self, placed: PlacedTests, out_dir: Path | None) -> StudentProcess:
        """A fresh sandboxed process for one notebook's cells."""
        notebook_timeout, budget = self._budgets()
        # RLIMIT_CPU is the kernel's last word on one process: never below the budget the
        # engine itself enforces, so an honest slow submission meets the engine's message.
        limits = self.policy.limits
        policy = replace(self.policy, limits=replace(
            limits, cpu_seconds=max(limits.cpu_seconds, int(budget) + 5)))
        return StudentProcess(
            slot=self._slot, cells=list(placed.cells), hidden_sources=placed.hidden_sources,
            data_files=self._data_files(), policy=policy,
            notebook_timeout=notebook_timeout, exclude=self._excluded_paths(out_dir),
            cpu_budget=budget, forbid=self.assignment.rules.to_wire(), otter=self._otter)

    def _budgets(self) -> tuple[float, float]:
        """The notebook's CPU time limit and the whole submission's CPU budget, in seconds."""
        return budgets(self.assignment, self.options)

    def wall_limit(self) -> float:
        """The most wall-clock seconds the student's code of one submission can hold the grader
        (see :func:`autograder.engine.student_process.wall_limit`)."""
        return wall_limit(*self._budgets())

    def _run_checks(self, target: Any, functions: Sequence[str], forbidden: dict[str, str],
                    seed: int, out_dir: Path | None, digest: str) -> tuple[CheckResult, ...]:
        context = self._context(target, functions, forbidden, seed, out_dir)
        checks = self._check_session(context, digest)
        try:
            run = checks.run(context)
        except BaseException:
            # A run that failed (an engine error, Ctrl-C) may have left fixtures set up or
            # items half run: that session is dropped, the next submission collects anew.
            self._checks = None
            checks.discard()
            raise
        if out_dir is not None and run.instructor_log:
            out_dir.mkdir(parents=True, exist_ok=True)
            (out_dir / "grader.log").write_text("\n\n".join(run.instructor_log))
        return run.results

    def _context(self, target: Any, functions: Sequence[str], forbidden: dict[str, str],
                 seed: int, out_dir: Path | None) -> CheckContext:
        return CheckContext(
            target=target, functions=tuple(functions), forbidden=forbidden,
            call_timeout=self.options.call_timeout or self.assignment.call_timeout, seed=seed,
            hidden_root=self.assignment.root / "checks" / "hidden",
            attachments=(out_dir / "images") if out_dir is not None else None,
            variant=self._variant,
            has_variants=self.assignment.variants is not None)

    def _check_session(self, context: CheckContext, digest: str) -> CheckSuite:
        """The pytest session of the checks: kept while the assignment folder is unchanged.

        A check file, a helper or a data file edited since the session was collected
        (``digest``, the assignment digest that keys every result, moved) closes it
        and collects the checks from disk again.
        """
        if self._checks is not None and self._checks_digest != digest:
            self._close_checks()
        if self._checks is None:
            self._checks = CheckSuite(self.check_files, self.assignment.root,
                                        name=self.assignment.name, context=context)
            self._checks_digest = digest
        return self._checks

    def _data_files(self) -> list[tuple[Path, str]]:
        root = self.assignment.root
        return [(p, str(p.relative_to(root))) for p in self.assignment.data_files]

    def _excluded_paths(self, out_dir: Path | None = None) -> list[Path]:
        """Trees the worker must never read: the assignment, the grader, other results,
        the folder of the submission being graded (the batch's other submissions)."""
        roots = {self.assignment.root.resolve(), self.assignment.root.resolve().parent}
        if out_dir is not None:  # the batch's result folder: every student's results
            roots.add(out_dir.resolve().parent)
        if self._source is not None:
            roots.add(self._source.resolve().parent)
        roots.update(forbidden_module_paths(self.assignment.rules))
        package = Path(autograder.__file__).resolve().parent
        roots.add(package)
        if (package.parent / "pyproject.toml").exists():  # an editable install: the repository
            roots.add(package.parent)
        return sorted(roots)


def with_variant(result: SubmissionResult, assignment: str, spec: VariantSpec,
                 variant: Variant | None, *,
                 submitted: dict[str, Any] | None = None) -> SubmissionResult:
    """``result`` with the student's variant recorded, and a note for a person when the id
    has no variant, the outputs match a classmate's variant (computed here, on the
    trusted side, from the outputs the checks recorded) or the notebook's parameters cell
    (``submitted``, its values) is not the student's own."""
    if variant is None:
        return replace(result, variant={"student": result.id, "seed": None, "params": None},
                       notes=result.notes + (
                           f"{SUBMISSION_NOTE}the id {result.id!r} is not on the roster of "
                           "this assignment's variants, so the checks that need the student's "
                           "parameters were not scored; find the student and grade by hand.",))
    observed = {k: v for t in result.tests for k, v in t.observed}
    roster = spec.students() or ()
    others = [spec.draw(assignment, s) for s in roster if s != variant.student]
    evidence = travel_evidence(variant, observed, others, spec.answers) if observed else []
    cell = cell_evidence(variant, submitted, others, secret_env=spec.secret_env,
                         active=spec.active())
    notes = tuple(f"{SUBMISSION_NOTE}an answer that travelled: {e}." for e in evidence) \
        + tuple(f"{SUBMISSION_NOTE}{e}." for e in cell)
    return replace(result, variant=variant.to_dict(), notes=result.notes + notes)


def summarise_run(run: NotebookRun, notebook: Notebook) -> str:
    """The student-facing summary of how the notebook ran."""
    parts = [f"Your notebook's {len(notebook.cells)} code cell(s) ran in {run.seconds:.1f} s."]
    if not notebook.cells:
        parts = ["Your notebook has no code to run: did you submit the right file?"]
    for index in run.timed_out_cells:
        parts.append(f"Cell {index + 1} did not finish within the time limit and was skipped; "
                     "the cells after it ran without it.")
    for index in run.crashed_cells:
        parts.append(f"Cell {index + 1} stopped the worker (it exited, hit a memory or CPU limit, "
                     "or broke its connection to the grader) and was skipped; the cells after it "
                     "ran without it.")
    errors = [c for c in run.cells if not c.ok]
    if errors:
        listed = "; ".join(f"cell {c.index + 1} ({c.ename}: {c.evalue[:120]})" for c in errors[:5])
        parts.append(f"{len(errors)} cell(s) raised an error: {listed}.")
    if run.violation:
        parts.append(f"{run.violation}.")
    if run.crashed:
        parts.append("The worker running your notebook stopped (it exited, or hit a memory "
                     "or CPU limit); checks that needed it were scored zero.")
    return " ".join(parts)


def without_cells(run: NotebookRun, indices: frozenset[int]) -> NotebookRun:
    """``run`` as the student's own cells ran: the test cells at ``indices`` left out."""
    return replace(run, cells=tuple(c for c in run.cells if c.index not in indices),
                   timed_out_cells=tuple(i for i in run.timed_out_cells if i not in indices),
                   crashed_cells=tuple(i for i in run.crashed_cells if i not in indices))


def withhold_check_output(tests: Sequence[CheckResult],
                          out_dir: Path | None) -> tuple[CheckResult, ...]:
    """The checks' results with their error text and pictures held back: they called the
    student's functions in a process a hidden test had entered, so a message or a
    figure could carry what the student's code read of it. Scores stay."""
    kept = []
    for test in tests:
        for picture in test.attachments:
            if out_dir is not None:
                (out_dir / picture.filename).unlink(missing_ok=True)
        output = WITHHELD if test.kind != "ok" and not test.hidden else test.output
        kept.append(replace(test, output=output, attachments=()))
    return tuple(kept)


def withhold_cell_errors(run: NotebookRun) -> NotebookRun:
    """``run`` with the errors of the cells from ``run.hidden_from`` on cut to "an error":
    their message could hold what the student's code read of a hidden test."""
    if run.hidden_from is None:
        return run
    after = run.hidden_from
    return replace(run, cells=tuple(
        replace(c, ename="Error", evalue="not shown (see the notes)", traceback="")
        if c.index >= after and not c.ok else c for c in run.cells))


def _in_section(part: SubmissionResult, section: str | None) -> SubmissionResult:
    """``part`` with its checks and cell errors marked as belonging to notebook ``section``."""
    if section is None:
        return part
    return replace(part, tests=tuple(replace(t, notebook=section) for t in part.tests),
                   cell_errors=tuple(replace(e, notebook=section) for e in part.cell_errors))


_WORST = ("error", "crashed", "timeout", "graded")


def _combined(assignment: str, named: list[tuple[str, SubmissionResult]],
              seed: int) -> SubmissionResult:
    """One result of the notebooks of a submission, their points summed."""
    if len(named) == 1:
        return named[0][1]
    parts = [p for _, p in named]
    outcomes = {p.outcome for p in parts}
    outcome: Any = ("ungradable" if outcomes == {"ungradable"} else
                    next(o for o in _WORST if o in outcomes or o == "graded"))
    output = "\n".join(f"{name}: {p.output}" for name, p in named)
    stdout = "".join(f"--- {name} ---\n{p.stdout}" for name, p in named if p.stdout)
    return replace(_result(assignment, outcome, output,
                           tuple(t for p in parts for t in p.tests), seed),
                   stdout=stdout, notes=_merged_notes(named),
                   cell_errors=tuple(e for p in parts for e in p.cell_errors),
                   cpu_seconds=round(sum(p.cpu_seconds for p in parts), 3))


def _merged_notes(named: list[tuple[str, SubmissionResult]]) -> tuple[str, ...]:
    """The notes of every notebook: one copy of those all share, the others named."""
    shared = set.intersection(*(set(p.notes) for _, p in named))
    notes = [n for n in named[0][1].notes if n in shared]
    notes += [f"{name}: {n}" for name, p in named for n in p.notes if n not in shared]
    return tuple(dict.fromkeys(notes))


def _result(assignment: str, outcome: Any, output: str, tests: tuple[CheckResult, ...],
            seed: int) -> SubmissionResult:
    return SubmissionResult(id="", source="", assignment=assignment, key="", sha256="",
                            outcome=outcome, output=output, tests=tests, execution_time=0.0,
                            seed=seed)


def _require_regular_file(path: Path) -> None:
    """Refuse links and special files: a submission is the student's own regular file.

    A link could name any file the grader can read (the instructor notebook, a
    classmate's submission); a FIFO or device could block or never end.
    """
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        raise NotebookError(f"{path.name!r} does not exist. Submit your .ipynb notebook file.",
                            kind="unreadable") from None
    except OSError as exc:
        raise NotebookError(f"{path.name!r} could not be read ({exc.strerror}). Submit it again.",
                            kind="unreadable") from None
    if stat.S_ISLNK(mode):
        raise NotebookError("This submission is a symbolic link, not a notebook file; submit "
                            "the .ipynb file itself.", kind="not-regular")
    if not stat.S_ISREG(mode):
        raise NotebookError("This submission is not a regular file (a folder, pipe or device); "
                            "submit the .ipynb file itself.", kind="not-regular")


__all__ = ["ENGINE_VERSION", "Grader", "GradingOptions", "assignment_digest", "engine_digest",
           "forget_check_modules", "submission_key", "submission_seed", "summarise_run"]


def error_result(assignment: Assignment, path: Path, sub_id: str, exc: BaseException | str) -> SubmissionResult:
    if isinstance(exc, BaseException):
        detail = "".join(traceback.format_exception_only(type(exc), exc)).strip()
    else:
        detail = exc
    return SubmissionResult(
        id=sub_id, source=str(path), assignment=assignment.name, key="",
        sha256=submission_sha256(path), outcome="error",
        output=f"The grader failed on this submission ({detail}); it will be regraded on the next run.",
        tests=(), execution_time=0.0, seed=0)


def client_key(path: Path, assignment: Assignment, options: GradingOptions) -> str:
    """The key a result of ``path`` must carry to be reused (computed where the file is)."""
    return submission_key(submission_sha256(path), assignment, options)
