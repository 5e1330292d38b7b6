"""What the static scan reports: each use of a forbidden name, and the findings of one scan.

Plain frozen data, made by :func:`autograder.engine.staticscan.scan` and read by
the forbidden-library rule (:mod:`autograder.engine.forbidden`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Use", "ScanFindings"]


@dataclass(frozen=True)
class Use:
    """One use of a forbidden (or unverifiable) name.

    Attributes
    ----------
    name : str
        The forbidden entry matched (``"scipy.spatial"``); for a dynamic use,
        what was called (``"exec"``, ``"importlib.import_module"``, ``"%run"``).
    function : str or None
        The top-level function (or class) whose body holds the use; ``None``
        at module level.
    cell : int
        Position of the cell in the ``sources`` given to
        :func:`~autograder.engine.staticscan.scan`.
    line : int
        Line in the cell, counting from 1.
    text : str
        That source line, stripped (and cut to 200 characters).
    """

    name: str
    function: str | None
    cell: int
    line: int
    text: str


@dataclass(frozen=True)
class ScanFindings:
    """What :func:`~autograder.engine.staticscan.scan` found.

    Attributes
    ----------
    uses : tuple of Use
        Every use of a forbidden name, sorted by cell and line.
    tainted : frozenset of str
        Top-level names that use a forbidden name directly or through other
        top-level names; a check calling one of them scores zero.
    dynamic : tuple of Use
        Code that could not be verified (``exec``, computed imports, ...).
    errors : tuple of str
        Cells (or magic bodies) that could not be parsed:
        ``"cell 2, line 3: invalid syntax"``; the other cells are still scanned.
    unverified : frozenset of str
        Top-level names reaching a dynamic use (directly or through others).
    """

    uses: tuple[Use, ...] = ()
    tainted: frozenset[str] = frozenset()
    dynamic: tuple[Use, ...] = ()
    errors: tuple[str, ...] = ()
    unverified: frozenset[str] = frozenset()
