"""Starting grading processes whose lives are tied to the service's (stdlib only).

A grading process is spawned (never forked: the web server has threads) and its
first act, before the heavy imports of the engine, is to ask the kernel for
SIGKILL when the service dies (``PR_SET_PDEATHSIG``) and to check the service
is still its parent (it may have died while the process was starting). The
kernel clears that request when a process's credentials change, which the
engine may do while setting up a slot, so a thread also watches the parent id
and ends the process when the service is gone. Either way no grading process
outlives a service killed with SIGKILL, and its unfinished job's lease runs out.
With ``--dask`` the one process started this way is the dispatcher
(:mod:`autograder.service.dispatch`); a ``local:N`` cluster's processes are its
children and end with it.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import threading
import time
from typing import Any

from autograder.service.settings import GraderSettings

_PR_SET_PDEATHSIG = 1
def _ask_kernel_to_kill_us() -> None:
    try:
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the watching thread still ends us
        pass


def _watch(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(1)  # the warm workers die with us (their own PR_SET_PDEATHSIG)


def grader_entry(settings: GraderSettings, stop: Any, name: str, parent: int,
                 wake: Any = None, graded: Any = None) -> None:
    """The target of a grading process: tie it to ``parent``, then run the grading loop
    (or, with ``settings.dask``, the dispatcher's: :mod:`autograder.service.dispatch`).
    ``wake`` is set when a job was queued (the loop then looks at once); the id of every
    submission recorded goes on ``graded`` (see :mod:`autograder.service.waits`)."""
    _ask_kernel_to_kill_us()
    if os.getppid() != parent:  # the service died while this process was starting
        os._exit(1)
    threading.Thread(target=_watch, args=(parent,), daemon=True, name="watch-service").start()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the service; it stops us
    if settings.dask is not None:
        from autograder.service.dispatch import dispatcher_main

        dispatcher_main(settings, stop, name, parent, wake, graded)
        return
    from autograder.service.graders import grader_main

    grader_main(settings, stop, name, parent, wake, graded)


class GradingPool:
    """``jobs`` grading processes pulling from the database queue; dead ones are replaced.

    With ``settings.dask``, give ``jobs=1``: one dispatcher sends the jobs to the cluster.
    """

    def __init__(self, settings: GraderSettings, jobs: int) -> None:
        self.settings = settings
        self.jobs = jobs
        self._context = multiprocessing.get_context("spawn")
        self._stop = self._context.Event()
        #: set when a job is queued: idle grading processes look at once (see wake)
        self._wake = self._context.Event()
        #: ids of the submissions the processes recorded, for the web process's waiting
        #: requests (a put never blocks: the queue's own thread writes the pipe)
        self.graded = self._context.Queue()
        self._procs: list[Any] = []
        self._closing = threading.Event()

    def start(self) -> None:
        for index in range(self.jobs):
            self._procs.append(self._spawn(index))
        threading.Thread(target=self._restart_dead, daemon=True, name="grading-pool").start()

    def _spawn(self, index: int) -> Any:
        # A dispatcher of a ``local:N`` cluster starts processes of its own, which a daemonic
        # process may not; stop() ends it either way, and the kernel does if the service dies.
        proc = self._context.Process(
            target=grader_entry, name=f"grader-{index}", daemon=self.settings.dask is None,
            args=(self.settings, self._stop, f"{os.getpid()}-{index}", os.getpid(), self._wake,
                  self.graded))
        proc.start()
        return proc

    def wake(self) -> None:
        """A job was queued: idle grading processes look now rather than at their next poll."""
        self._wake.set()

    def _restart_dead(self) -> None:
        """A grading process that died (out of memory, say) is replaced."""
        while not self._closing.wait(1.0):
            for index, proc in enumerate(self._procs):
                if not proc.is_alive() and not self._closing.is_set():
                    self._procs[index] = self._spawn(index)

    def stop(self, timeout: float = 30.0) -> None:
        self._closing.set()
        self._stop.set()
        self._wake.set()
        deadline = time.monotonic() + timeout
        for proc in self._procs:
            proc.join(max(0.1, deadline - time.monotonic()))
            if proc.is_alive():
                proc.kill()
                proc.join(5)
        self.graded.put(None)  # ends the web process's relay thread
