"""Worker plugins that make Dask workers die on purpose, for the failure tests.

Shipped to the workers by value (``cloudpickle.register_pickle_by_value``), so
the worker processes need not import this file.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import cloudpickle
import dask
from distributed import Client, WorkerPlugin


class KillWhenGrading(WorkerPlugin):
    """Ends the worker process when it starts grading a chosen submission.

    ``once``: ids whose first attempt dies ``delay`` seconds into the grading
    (a marker file under ``marks`` remembers it across worker restarts);
    ``always``: ids whose every attempt kills the worker at once, except that
    with ``witnesses`` the first attempt of each waits until a task of every
    witness id is on this worker too, so that Dask certainly counts that death
    against the witnesses as well (a marker ``<id>.shared`` remembers it).
    """

    name = "test-kill-when-grading"

    def __init__(self, marks: Path, *, once: tuple[str, ...] = (), always: tuple[str, ...] = (),
                 delay: float = 0.5, witnesses: tuple[str, ...] = ()) -> None:
        self.marks, self.once, self.always, self.delay = str(marks), once, always, delay
        self.witnesses = witnesses
        self._seen: set[str] = set()
        self._waiting = False  # an `always` grading is executing, waiting for the witnesses

    def _first_time(self, name: str) -> bool:
        try:
            fd = os.open(Path(self.marks) / name, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return False
        os.close(fd)
        return True

    def transition(self, key, start, finish, **kwargs) -> None:  # noqa: ANN001 (Dask's signature)
        if not isinstance(key, str) or not key.startswith("grade-"):
            return
        sub_id = key.removeprefix("grade-").rsplit("-", 1)[0]
        if sub_id in self.witnesses:
            self._seen.add(sub_id)
            if self._waiting and self._seen >= set(self.witnesses):
                os._exit(17)
        if finish != "executing":
            return
        if sub_id in self.always:
            if self.witnesses and self._first_time(f"{sub_id}.shared") \
                    and not self._seen >= set(self.witnesses):
                self._waiting = True  # dies when the last witness arrives here
                return
            os._exit(17)
        if sub_id in self.once and self._first_time(sub_id):
            threading.Timer(self.delay, os._exit, args=(17,)).start()


@contextmanager
def shared_death_cluster(marks: Path, *, killer: str, witness: str) -> Iterator[str]:
    """A cluster where ``killer``'s grading kills the only worker while ``witness``'s waits there.

    One worker process with two grading slots (so both gradings are sent to it), no
    death allowed per task (Dask fails every task on the worker at its first death),
    and :class:`KillWhenGrading` with ``witness`` as the witness: every grading of
    ``killer`` kills the worker, the first once ``witness``'s grading is on it too.
    Yields the scheduler's address.
    """
    from autograder.runners.dask_cluster import RESOURCE, local_cluster

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        cluster = local_cluster(1, resources={RESOURCE: 2})
    with cluster, Client(cluster) as client:
        client.register_plugin(KillWhenGrading(marks, always=(killer,), witnesses=(witness,)))
        yield cluster.scheduler_address
