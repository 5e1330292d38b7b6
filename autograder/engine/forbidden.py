"""The forbidden-library rule of an assignment: what is forbidden, and what follows from it.

An assignment may forbid libraries (``[rules]`` in ``assignment.toml``: ``forbid``,
``reason``, ``internal_use``; read by :mod:`autograder.engine.assignment` into
:class:`Rules`). The grader enforces the rule in three places, each fed from here:

1. the static scan (:mod:`autograder.engine.staticscan`) of the cells names each
   use: a check that calls a student function using a forbidden name scores zero
   with the rule's reason (:func:`forbidden_functions`), and code the scan cannot
   verify gets a note for a person (:func:`review_notes`);
2. the worker's guard (:mod:`autograder.worker.guard`) blocks the libraries at
   run time, whatever the spelling; the worker may not import the engine, so the
   rule reaches it as plain data in the spawn request (:meth:`Rules.to_wire`);
3. the sandbox keeps the forbidden packages' files out of the worker's reach
   (:func:`forbidden_module_paths`, among the grader's excluded paths), except
   the names an allowed library needs inside (``internal_use``).
"""

from __future__ import annotations

import functools
import importlib.util
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from autograder.engine import staticscan
from autograder.engine.scanfindings import ScanFindings

__all__ = ["REVIEW_PREFIX", "Rules", "scan_sources", "warm_up", "forbidden_functions",
           "review_notes", "forbidden_module_paths"]

#: how a note that asks for a person starts (the class summary lists such submissions)
REVIEW_PREFIX = "For the instructor: "


@dataclass(frozen=True)
class Rules:
    """What the static scan forbids, and the reason shown to the student.

    Attributes
    ----------
    forbid : tuple of str
        Dotted names: a module (``"scipy.spatial"``, everything under it) or an
        attribute (``"scipy.interpolate.CubicSpline"``).
    reason : str
        The message given with a zero score for a forbidden use.
    """

    forbid: tuple[str, ...] = ()
    reason: str = ""
    #: forbidden names that allowed libraries need inside (``matplotlib.path`` for
    #: drawing): student code may not name them, and in the worker they answer calls
    #: from that library's code only
    internal_use: tuple[str, ...] = ()

    def to_wire(self) -> dict[str, object]:
        """The plain data the worker's guard takes (see ``autograder.worker.guard``)."""
        return {"names": list(self.forbid), "internal_use": list(self.internal_use),
                "reason": self.reason}


def scan_sources(rules: Rules, sources: Sequence[str]) -> ScanFindings:
    """The static scan of a submission's cells; empty findings when nothing is forbidden."""
    return staticscan.scan(sources, rules.forbid) if rules.forbid else ScanFindings()


def warm_up(rules: Rules) -> None:
    """An empty scan when something is forbidden: the scan's modules are imported before
    the first submission needs them (IPython only on the first cell in IPython syntax)."""
    if rules.forbid:
        staticscan.scan((), rules.forbid)


def forbidden_functions(rules: Rules, sources: Sequence[str], cell_numbers: Sequence[int],
                        report: ScanFindings | None = None) -> dict[str, str]:
    """Map each student function that uses a forbidden name to the message for it."""
    if not rules.forbid:
        return {}
    report = report or staticscan.scan(sources, rules.forbid)
    messages: dict[str, str] = {}
    for function in sorted(report.tainted):
        use = next((u for u in report.uses if u.function == function), None) or \
            next((u for u in report.uses if u.function is not None), None)
        where = ""
        if use is not None:
            cell = cell_numbers[use.cell] if use.cell < len(cell_numbers) else use.cell
            where = f" (`{use.name}` in cell {cell + 1}, line {use.line})"
        messages[function] = (f"`{function}` uses a name this assignment does not allow{where}. "
                              f"{rules.reason}")
    return messages


def review_notes(report: ScanFindings, cell_numbers: Sequence[int]) -> tuple[str, ...]:
    """Notes for the "needs a person" list: code the scan could not verify.

    The worker's guard still blocks forbidden libraries at run time whatever the
    spelling; these notes let a person see why the scan could not tell.
    """
    if not report.dynamic:
        return ()
    places = "; ".join(
        f"`{use.name}` in cell {(cell_numbers[use.cell] if use.cell < len(cell_numbers) else use.cell) + 1}"
        f", line {use.line}" for use in report.dynamic[:5])
    reaching = ", ".join(sorted(report.unverified)[:10]) or "no top-level function"
    return (f"{REVIEW_PREFIX}the code scan could not verify {len(report.dynamic)} place(s) "
            f"({places}); reached from: {reaching}.",)


def forbidden_module_paths(rules: Rules) -> tuple[Path, ...]:
    """Files and folders of the forbidden modules, kept out of the worker's reach.

    Names an allowed library needs inside (``[rules] internal_use``) stay readable.
    """
    return _module_paths(tuple(n for n in rules.forbid if n not in rules.internal_use))


@functools.lru_cache(maxsize=32)
def _module_paths(names: tuple[str, ...]) -> tuple[Path, ...]:
    found: list[Path] = []
    for name in names:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError, AttributeError):  # not installed, or an attribute
            continue
        if spec is None:
            continue
        if spec.submodule_search_locations:
            found += [Path(p).resolve() for p in spec.submodule_search_locations]
        elif spec.origin and os.path.isabs(spec.origin):
            found.append(Path(spec.origin).resolve())
    return tuple(found)
