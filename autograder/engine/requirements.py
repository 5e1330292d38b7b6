"""Check, before the first submission, that every package an assignment needs imports in the worker.

An assignment lists what its students' code needs beyond numpy, scipy and
matplotlib (``[assignment] requirements = ["pandas>=2"]``, or otter's
``requirements.txt``). A package that is missing, too old, or unreadable inside
the sandbox would make every submission's ``import pandas`` fail: a class of
silent zeros. So grading starts by checking each requirement twice:

1. on the grader's side, that the distribution is installed in the Python the
   worker runs (the same interpreter, forked) at a version the requirement allows
   (``packaging`` parses it, ``importlib.metadata`` gives the version);
2. in a sandboxed worker with the same policy and readable paths as a
   submission's, that each of its top-level modules imports.

The first failure raises :class:`~autograder.errors.AssignmentError` naming the
package and the pip command that installs it, before any result is written.
"""

from __future__ import annotations

import importlib.metadata
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

from autograder.errors import AssignmentError, UsageError

if TYPE_CHECKING:
    from packaging.requirements import Requirement

__all__ = ["Needed", "parse_requirements", "check_installed", "probe_cells", "check_requirements"]


@dataclass(frozen=True)
class Needed:
    """One requirement: the text as written, the distribution, the modules it provides."""

    text: str
    distribution: str
    modules: tuple[str, ...]

    @property
    def pip(self) -> str:
        """The command that installs it into the grader's Python."""
        return f"{shlex.quote(sys.executable)} -m pip install {shlex.quote(self.text)}"


def parse_requirements(texts: Sequence[str], *, where: str) -> tuple[Requirement, ...]:
    """Each text as a :class:`packaging.requirements.Requirement`; a bad one names ``where``."""
    try:  # here: only an assignment with requirements needs it
        from packaging.requirements import InvalidRequirement, Requirement
    except ImportError:
        raise UsageError("Checking an assignment's requirements needs the 'packaging' "
                         "library: python -m pip install packaging.") from None
    parsed = []
    for text in texts:
        try:
            parsed.append(Requirement(text))
        except InvalidRequirement as exc:
            raise AssignmentError(f"{where}: requirement {text!r} cannot be read ({exc}); write "
                                  "it as pip does, for example \"pandas>=2\".") from None
    return tuple(parsed)


def _modules(distribution: importlib.metadata.Distribution, name: str) -> tuple[str, ...]:
    """The top-level modules a distribution installs (``top_level.txt``, else its files)."""
    listed = (distribution.read_text("top_level.txt") or "").split()
    if not listed:
        listed = sorted({Path(str(f)).parts[0].removesuffix(".py") for f in distribution.files or ()
                         if str(f).endswith(".py") and "/" in str(f).replace("\\", "/")
                         and not str(f).startswith(("..", "bin/"))
                         and not Path(str(f)).parts[0].endswith((".dist-info", ".egg-info"))})
    modules = tuple(m for m in listed if m.isidentifier() and not m.startswith("_"))
    return modules or (name.replace("-", "_").lower(),)


def check_installed(texts: Sequence[str], *, where: str) -> tuple[Needed, ...]:
    """Each requirement installed at an allowed version, in this (the worker's) Python.

    Raises
    ------
    AssignmentError
        A requirement that does not parse, is not installed, or whose installed
        version it does not allow; the message gives the pip command.
    """
    needed = []
    for text, requirement in zip(texts, parse_requirements(texts, where=where)):
        item = Needed(text, requirement.name, ())
        try:
            distribution = importlib.metadata.distribution(requirement.name)
        except importlib.metadata.PackageNotFoundError:
            raise AssignmentError(
                f"{where} needs {text!r}, and {requirement.name} is not installed in the "
                f"Python that grades ({sys.executable}); install it with: {item.pip}") from None
        version = distribution.version
        if requirement.specifier and not requirement.specifier.contains(version, prereleases=True):
            raise AssignmentError(
                f"{where} needs {text!r}, and {requirement.name} {version} is installed; "
                f"install a version it allows with: {item.pip}")
        needed.append(Needed(text, requirement.name, _modules(distribution, requirement.name)))
    return tuple(needed)


def probe_cells(needed: Sequence[Needed]) -> list[tuple[int, str]]:
    """One cell per module to import, numbered in order (the worker runs them as a notebook)."""
    modules = [m for item in needed for m in item.modules]
    return [(i, f"import {module}") for i, module in enumerate(modules)]


#: runs cells in a sandboxed worker like a submission's; per cell (ok, "Error: message")
RunCells = Callable[[list[tuple[int, str]]], list[tuple[bool, str]]]


def check_requirements(texts: Sequence[str], run_cells: RunCells, *, where: str) -> None:
    """Check every requirement installed, then every module importing in the worker.

    Raises
    ------
    AssignmentError
        The first requirement that fails either step, with the pip command.
    """
    if not texts:
        return
    needed = check_installed(texts, where=where)
    cells = probe_cells(needed)
    outcomes = run_cells(cells)
    owners = [item for item in needed for _ in item.modules]
    for (_, source), item, (ok, error) in zip(cells, owners, outcomes, strict=True):
        if not ok:
            raise AssignmentError(
                f"{where} needs {item.text!r}, and `{source}` fails in the sandboxed worker "
                f"({error}). If the package is damaged or incomplete, reinstall it with: "
                f"{item.pip} --force-reinstall; if it is installed outside the folders the "
                "sandbox lets students read, see 'Troubleshooting' in docs/install.md.")
