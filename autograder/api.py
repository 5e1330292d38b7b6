"""The Python API behind the command line: keyword-only functions holding the defaults."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

from autograder.authoring.gradescope import GRADESCOPE_ROOT, gradescope_zip, run_submission
from autograder.authoring.release import release as _release, release_variants
from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.grader import Grader, GradingOptions
from autograder.engine.slot import GradingSlot
from autograder.results import exports
from autograder.results.model import SubmissionResult
from autograder.runners.batch import BatchRun, Shard, grade_batch
from autograder.runners.jobs import DaskSpec, TLSFiles

if TYPE_CHECKING:
    from autograder.authoring.validate import ValidationRun
    from autograder.results.merge import MergeRun


def resolve_assignment(spec: str | Path | Assignment, *, course: Path | None = None) -> Assignment:
    """An :class:`Assignment` from a name under ``assignments/``, a folder, or itself.

    ``course``: an nbgrader course root, where a name is a folder under ``source/``.
    """
    if isinstance(spec, Assignment):
        return spec
    return load_assignment(spec, search_root=course) if course is not None else load_assignment(spec)


def release(assignment: str | Path | Assignment, *, out: Path,
            variants: Path | None = None, server: str | None = None) -> Path:
    """Write the student version of ``assignment`` to ``out``; return the notebook path.

    ``variants``: a roster CSV; one notebook per student is written to
    ``out/<student>/`` with the student's parameters, and the first is returned.
    ``server``: the course's service, written into the notebooks for ``submit()``.
    """
    if variants is not None:
        return release_variants(resolve_assignment(assignment), Path(variants), Path(out),
                                server=server)[0]
    return _release(resolve_assignment(assignment), Path(out), server=server)


def grade(assignment: str | Path | Assignment, submissions: Sequence[Path], *, out: Path,
          jobs: int | None = None, options: GradingOptions | None = None,
          progress: bool | None = None,
          on_result: Callable[[SubmissionResult], None] | None = None,
          junit: Path | None = None, dask: DaskSpec | str | None = None,
          shard: Shard | str | None = None, started_slot: GradingSlot | None = None) -> BatchRun:
    """Grade notebooks (files or folders) into ``out``; see :func:`autograder.runners.batch.grade_batch`.

    ``junit``, when given, is a file for the JUnit XML report of every result in
    ``out``. ``dask`` (a :class:`DaskSpec`, or an address such as ``"local:2"``)
    grades on a Dask cluster instead of ``jobs`` local processes; ``shard``
    (``"K/N"``) grades only that share of the submissions. ``started_slot``, a slot from
    :func:`autograder.engine.slot.start_early`, is the first local slot; the caller closes
    it after the call (the command line starts it before importing the engine).
    """
    found = resolve_assignment(assignment)
    report = grade_batch(found, [Path(s) for s in submissions], Path(out),
                         jobs=jobs, options=options, progress=progress, on_result=on_result,
                         dask=DaskSpec(dask) if isinstance(dask, str) else dask,
                         shard=Shard.parse(shard) if isinstance(shard, str) else shard,
                         started_slot=started_slot)
    if junit is not None:
        exports.write_junit(Path(junit), report.folder, name=found.name)
    return report


def merge(folders: Sequence[Path], *, out: Path, assignment: str | Path | Assignment | None = None,
          junit: Path | None = None) -> "MergeRun":
    """Merge shard result folders into ``out`` with ``grades.csv``, the summary and, if asked, JUnit.

    ``assignment``, when given, only supplies the summary's title.
    """
    from autograder.results.merge import merge_results

    title = resolve_assignment(assignment).title if assignment is not None else None
    report = merge_results([Path(f) for f in folders], out=Path(out), title=title)
    if junit is not None:
        name = report.results[0].assignment if report.results else ""
        exports.write_junit(Path(junit), report.results, name=name)
    return report


def run_worker(address: str, *, slots: int = 1, tls: TLSFiles | None = None,
               insecure: bool = False) -> None:
    """Serve ``slots`` grading slots to the Dask scheduler at ``address`` until stopped.

    Needs the ``dask`` extra (``pip install "numgrade[dask]"``).
    """
    from autograder.runners.backends import load_dask_backend

    load_dask_backend().run_worker(address, slots=slots, tls=tls, insecure=insecure)


def ci_report(report: BatchRun, *, step_summary: Path | None = None) -> list[str]:
    """The lines a CI log needs (``Points X/Y`` per submission, for GitHub Classroom).

    ``step_summary``, when given (GitHub's ``$GITHUB_STEP_SUMMARY``), gets a
    Markdown report of the batch appended.
    """
    if step_summary is not None:
        exports.append_step_summary(Path(step_summary), report.results)
    return exports.ci_lines(report.results)


def gradescope(assignment: str | Path | Assignment, *, out: Path) -> Path:
    """Write the autograder zip Gradescope takes for ``assignment`` into ``out``; return its path."""
    return gradescope_zip(resolve_assignment(assignment), Path(out))


def gradescope_run(root: str | Path = GRADESCOPE_ROOT) -> int:
    """Grade a submission the Gradescope way; what the zip's ``run_autograder`` calls.

    Reads the notebook from ``root/submission/``, the assignment from
    ``root/source/assignment/<name>/`` and writes ``root/results/results.json``
    (pictures in ``root/results/images/``). A grader failure is written as an
    "error" result, so Gradescope always gets a ``results.json``. Returns 0.
    """
    run_submission(Path(root))
    return 0


def new(name: str, *, out: Path | None = None, title: str | None = None) -> Path:
    """Write a working assignment folder ``out/name`` (see :mod:`autograder.authoring.scaffold`).

    ``out`` defaults to ``./assignments`` when the current folder has one, else
    the current folder. Returns the new folder.
    """
    from autograder.authoring.scaffold import new_assignment

    if out is None:
        out = Path("assignments") if Path("assignments").is_dir() else Path(".")
    return new_assignment(name, out=Path(out), title=title)


def validate(assignment: str | Path | Assignment, *, work: Path | None = None,
             jobs: int | None = None, options: GradingOptions | None = None,
             started_slot: GradingSlot | None = None, mutants: bool = False,
             max_mutants: int | None = None) -> "ValidationRun":
    """Release ``assignment``, check nothing leaked, grade its examples and the
    released template, and compare each score with its band in
    ``examples/expected.toml`` (see :mod:`autograder.authoring.validate`).

    ``work``, when given, keeps the release and the results (feedback pages) there.
    ``started_slot``: as for :func:`grade`. ``mutants``: also grade mutants of the
    model solution (:mod:`autograder.authoring.mutants_run`), at most ``max_mutants``.
    """
    from autograder.authoring.validate import validate as _validate

    return _validate(resolve_assignment(assignment), work=None if work is None else Path(work),
                     jobs=jobs, options=options, started_slot=started_slot, mutants=mutants,
                     max_mutants=max_mutants)


def check(notebook: Path, *, assignment: str | Path | Assignment | None = None,
          options: GradingOptions | None = None,
          started_slot: GradingSlot | None = None,
          out_dir: Path | None = None) -> SubmissionResult:
    """Run the public checks on one notebook, as a student does before submitting.

    ``started_slot``: as for :func:`grade`. ``out_dir``, when given, receives the result
    folder (the feedback page and its pictures).
    """
    notebook = Path(notebook)
    found = resolve_assignment(assignment) if assignment is not None else _guess(notebook)
    base = options or GradingOptions()
    opts = GradingOptions(policy=base.policy, notebook_timeout=base.notebook_timeout,
                          call_timeout=base.call_timeout, public_only=True,
                          max_notebook_bytes=base.max_notebook_bytes)
    # An assignment of several notebooks is checked whole: the folder the notebook sits
    # in holds the others, each found by its file name (a missing one is named).
    target = notebook.parent if len(found.notebooks) > 1 and notebook.is_file() else notebook
    with Grader(found, opts, started_slot=started_slot) as grader:
        return grader.grade(target, out_dir=None if out_dir is None else Path(out_dir))


def _guess(notebook: Path) -> Assignment:
    """The released folder the notebook sits in, else the assignment named like the notebook."""
    folder = notebook.resolve().parent
    if (folder / "assignment.toml").exists():
        return load_assignment(folder)
    return load_assignment(notebook.stem)
