"""The released notebook students download: made by ``autograder release``, cached per version.

The service room does not import ``authoring`` (nbgrader is the instructor's
tool, heavy to import, and the release is the one place a solution is cut out),
so the student version is made by the real ``autograder release`` in a child
process, with its check that no solution or hidden check is left in the output.
It is kept under ``<data>/released/<name>/<sha>/``, where ``sha`` covers every
file of the assignment folder: an edited notebook or check makes a new release
at the next download, never a stale one.

An assignment with per-student variants (``[variants]``) hands each student the
released notebook with its parameters cell holding their own parameters, drawn
on the trusted side from the course secret (:mod:`autograder.engine.variants`),
as ``autograder release --variants`` writes it.
"""

from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import nbformat

from autograder.engine.assignment import Assignment, load_assignment
from autograder.engine.variants import parameters_source
from autograder.errors import UsageError
from autograder.service.course import AssignmentPolicy

#: nbgrader's preprocessors on a class notebook take seconds; a minute is generous
RELEASE_TIMEOUT = 300.0


def _version(assignment: Assignment) -> str:
    """SHA-256 over the assignment folder's file names and contents."""
    digest = hashlib.sha256()
    for path in sorted(p for p in assignment.root.rglob("*") if p.is_file()):
        digest.update(str(path.relative_to(assignment.root)).encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()[:24]


def released_notebook(policy: AssignmentPolicy, data_dir: Path) -> Path:
    """The student version of ``policy``'s (first) notebook, made on first use.

    Raises
    ------
    UsageError
        ``autograder release`` refused the assignment (its message says why).
    """
    assignment = load_assignment(policy.spec)
    folder = data_dir / "released" / policy.name / _version(assignment)
    target = folder / assignment.notebook.name
    if target.is_file():
        return target
    folder.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".making-", dir=folder.parent))
    try:
        done = subprocess.run(
            [sys.executable, "-m", "autograder", "release", str(assignment.root),
             "--out", str(work / "out")], capture_output=True, text=True,
            timeout=RELEASE_TIMEOUT)
        if done.returncode != 0:
            raise UsageError(f"The released notebook of {policy.name!r} could not be made: "
                             f"{(done.stderr or done.stdout).strip()[-800:]}")
        try:  # two downloads at once: the first rename wins, the second finds it there
            (work / "out").rename(folder)
        except OSError:
            if not target.is_file():
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return target


def students_notebook(policy: AssignmentPolicy, released: Path, student: str) -> bytes | None:
    """``student``'s own copy of the released notebook ``released`` (from
    :func:`released_notebook`) for a variants assignment; ``None``: the assignment has no
    variants, or no course secret is set: everyone gets ``released`` itself.

    Raises
    ------
    LookupError
        The student is not on the variants roster.
    UsageError
        The notebook has no single parameters cell.
    """
    assignment = load_assignment(policy.spec)
    spec = assignment.variants
    if spec is None or not spec.active():  # no secret: everyone has the instructor's values
        return None
    variant = spec.lookup(assignment.name, student)
    if variant is None:
        raise LookupError(f"{policy.title} gives every student their own problem, and {student!r} "
                         "is not on its roster of variants; ask your instructor to add you.")
    book = nbformat.read(str(released), as_version=4)
    cells = [c for c in book.cells if spec.cell in c.get("metadata", {}).get("tags", [])]
    if len(cells) != 1:
        raise UsageError(f"The notebook of {policy.name!r} has {len(cells)} cells tagged "
                         f"{spec.cell!r}; it needs exactly one (its parameters cell).")
    cells[0].source = parameters_source(variant)
    return nbformat.writes(book).encode()
