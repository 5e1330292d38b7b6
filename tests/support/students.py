"""A ``student`` proxy over a real sandboxed worker running a notebook given as one code cell."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from autograder.engine.proxy import CallLog, Student
from autograder.engine.slot import GradingSlot
from autograder.engine.student_process import StudentProcess
from autograder.sandbox.policy import IsolationPolicy


@contextlib.contextmanager
def running(slot: GradingSlot, code: str, *, timeout: float = 5) -> Iterator[Student]:
    """``code`` run in a worker of ``slot`` (every cell must succeed), and its proxy;
    ``timeout`` is each call's CPU limit. The worker is closed after."""
    session = StudentProcess(slot=slot, cells=[(0, code)], data_files=[],
                             policy=IsolationPolicy(), notebook_timeout=60)
    try:
        report = session.start()
        assert all(cell.ok for cell in report.cells), report.cells
        yield Student(session, timeout=timeout, functions=report.functions, forbidden={},
                      log=CallLog())
    finally:
        session.close()
