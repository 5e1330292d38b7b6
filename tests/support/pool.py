"""The pool processes of a ``--jobs N`` batch run in this process (:mod:`autograder.runners.local`).

The first pool is forked from the batch's process when it runs no other thread, and
spawned otherwise (a pytest process may still hold a thread of an earlier test); a
test that looks for the pool finds it either way.
"""

from __future__ import annotations

import os
import threading
from typing import Any, Callable

import psutil

from autograder.results.model import SubmissionResult


def pool_processes() -> list[psutil.Process]:
    """This process's pool processes: forked (this process's command line) or spawned."""
    me = psutil.Process()
    ours = me.cmdline()
    found = []
    for child in me.children():
        try:
            line = child.cmdline()
        except psutil.Error:
            continue
        if line == ours or "spawn_main" in " ".join(line):
            found.append(child)
    return found


def slot_zero_waits(event: threading.Event,
                    grade: Callable[..., SubmissionResult]) -> Callable[..., SubmissionResult]:
    """``grade`` (``local.grade_one``) made to wait for ``event`` in this process only.

    Slot 0 then grades only once the pool graded a file, however fast it is. A forked
    pool process inherits the patch with the module; there it grades at once (its copy
    of ``event`` is never set).
    """
    batch = os.getpid()

    def wrapped(*args: Any, **kwargs: Any) -> SubmissionResult:
        if os.getpid() == batch:
            event.wait(timeout=600)
        return grade(*args, **kwargs)

    return wrapped
