"""Which core a worker slot runs on: its warm parent, its children and, during a submission,
the grader thread that talks to them.

A check calls the student's functions one at a time: the grader sends a request,
waits, and the child answers, so the two processes never need to run at the same
time. Left to itself, the kernel puts them on two idle cores, and every message
then wakes a sleeping core. On the 2-core virtual machines this project measures
on, that made a framed round trip cost about 110 microseconds of CPU on each side
against 28 on one core, and a hull submission with every check 203 ms of CPU
against 162 ms (``benchmarks/call_costs.py``, ``taskset`` beside it).

Slot ``k`` runs on the ``k``-th core of those this process may use (modulo their
number). Slot numbers are unique among the graders of one user on one machine
(:func:`autograder.engine.slot.claim_slot`), so ``--jobs N`` slots, Dask workers and
service workers of one user spread over the cores. The grader thread is put on its
slot's core only while a submission's child lives, and back where it was after:
checks collected and results written meanwhile run wherever the kernel likes.

Time limits are CPU seconds, so a verdict does not depend on the core; student code
that starts threads shares its one core (NumPy's own thread pools are already
limited to one thread in the worker). On a machine shared with another grader of
another user, both may be given the same core:
``AUTOGRADER_PIN_CORES=0`` turns this off.

Why by hand: ``os.sched_setaffinity`` is the whole interface; psutil's
``cpu_affinity`` is the same call and not a dependency of the engine.
"""

from __future__ import annotations

import contextlib
import os
from typing import Iterator

from autograder.errors import UsageError

__all__ = ["ENVIRONMENT_VARIABLE", "on_core", "pin_process", "slot_core"]

#: set to ``0`` to let the kernel place every process and thread as it likes
ENVIRONMENT_VARIABLE = "AUTOGRADER_PIN_CORES"


def _enabled() -> bool:
    value = os.environ.get(ENVIRONMENT_VARIABLE, "1").strip().lower()
    if value in ("1", "yes", "on", "true", ""):
        return True
    if value in ("0", "no", "off", "false"):
        return False
    raise UsageError(f"{ENVIRONMENT_VARIABLE} (from the environment) must be 1 or 0; got "
                     f"{os.environ[ENVIRONMENT_VARIABLE]!r}. Unset it to run each worker slot "
                     "on one core, or set it to 0 to let the kernel place them.")


def slot_core(slot: int) -> int | None:
    """The core slot ``slot`` runs on, or None: pinning is off, this process may use only
    one core, or the system has no affinity interface."""
    if not _enabled():
        return None
    try:
        cores = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux, or not allowed
        return None
    if len(cores) < 2:
        return None
    return cores[slot % len(cores)]


def pin_process(pid: int, core: int | None) -> None:
    """Put the process ``pid`` (its main thread, and every thread and child it starts
    later) on ``core``; nothing if ``core`` is None or the kernel refuses."""
    if core is None:
        return
    with contextlib.suppress(OSError):  # gone already, or the core is not ours any more
        os.sched_setaffinity(pid, {core})


@contextlib.contextmanager
def on_core(core: int | None) -> Iterator[None]:
    """Run the calling thread on ``core`` inside the block, and where it could run before after.

    Linux applies ``sched_setaffinity(0, ...)`` to the calling thread only, so other
    threads of this process (a progress bar, a pool's feeder) are not moved.
    """
    if core is None:
        yield
        return
    try:
        before = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {core})
    except OSError:  # the core is not ours any more (a changed cpuset): run unpinned
        yield
        return
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.sched_setaffinity(0, before)
