"""The Python API behind the command line: keyword-only functions holding the defaults."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

from autograder.assignment import Assignment, load_assignment
from autograder.batch import BatchReport, grade_batch
from autograder.grading import Grader, GradingOptions
from autograder.release import release as _release
from autograder.results import SubmissionResult


def resolve_assignment(spec: str | Path | Assignment) -> Assignment:
    """An :class:`Assignment` from a name under ``assignments/``, a folder, or itself."""
    return spec if isinstance(spec, Assignment) else load_assignment(spec)


def release(assignment: str | Path | Assignment, *, out: Path) -> Path:
    """Write the student version of ``assignment`` to ``out``; return the notebook path."""
    return _release(resolve_assignment(assignment), Path(out))


def grade(assignment: str | Path | Assignment, submissions: Sequence[Path], *, out: Path,
          jobs: int | None = None, options: GradingOptions | None = None,
          progress: bool | None = None,
          on_result: Callable[[SubmissionResult], None] | None = None) -> BatchReport:
    """Grade notebooks (files or folders) into ``out``; see :func:`autograder.batch.grade_batch`."""
    return grade_batch(resolve_assignment(assignment), [Path(s) for s in submissions], Path(out),
                       jobs=jobs, options=options, progress=progress, on_result=on_result)


def check(notebook: Path, *, assignment: str | Path | Assignment | None = None,
          options: GradingOptions | None = None) -> SubmissionResult:
    """Run the public checks on one notebook, as a student does before submitting."""
    notebook = Path(notebook)
    found = resolve_assignment(assignment) if assignment is not None else _guess(notebook)
    base = options or GradingOptions()
    opts = GradingOptions(policy=base.policy, notebook_timeout=base.notebook_timeout,
                          call_timeout=base.call_timeout, public_only=True,
                          max_notebook_bytes=base.max_notebook_bytes)
    with Grader(found, opts) as grader:
        return grader.grade(notebook)


def _guess(notebook: Path) -> Assignment:
    """The released folder the notebook sits in, else the assignment named like the notebook."""
    folder = notebook.resolve().parent
    if (folder / "assignment.toml").exists():
        return load_assignment(folder)
    return load_assignment(notebook.stem)
