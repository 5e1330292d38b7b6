"""Tests written as notebook cells (nbgrader's autograder cells, otter's test cases).

A course that comes from nbgrader or otter keeps its tests in the notebook rather
than in pytest files. Each such test is one :class:`CellTest`: code that runs in
the student's sandboxed process, after (or in place of) a cell of the student's
notebook, and earns its points when it runs without raising.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CellTest"]


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
