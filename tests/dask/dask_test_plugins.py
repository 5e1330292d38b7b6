"""Worker plugins that make Dask workers die on purpose, for the failure tests.

Shipped to the workers by value (``cloudpickle.register_pickle_by_value``), so
the worker processes need not import this file.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

from distributed import WorkerPlugin


class KillWhenGrading(WorkerPlugin):
    """Ends the worker process when it starts grading a chosen submission.

    ``once``: ids whose first attempt dies ``delay`` seconds into the grading
    (a marker file under ``marks`` remembers it across worker restarts);
    ``always``: ids whose every attempt kills the worker at once.
    """

    name = "test-kill-when-grading"

    def __init__(self, marks: Path, *, once: tuple[str, ...] = (), always: tuple[str, ...] = (),
                 delay: float = 0.5) -> None:
        self.marks, self.once, self.always, self.delay = str(marks), once, always, delay

    def transition(self, key, start, finish, **kwargs) -> None:  # noqa: ANN001 (Dask's signature)
        if finish != "executing" or not isinstance(key, str) or not key.startswith("grade-"):
            return
        sub_id = key.removeprefix("grade-").rsplit("-", 1)[0]
        if sub_id in self.always:
            os._exit(17)
        if sub_id in self.once:
            marker = Path(self.marks) / sub_id
            try:
                fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
            except FileExistsError:
                return
            os.close(fd)
            threading.Timer(self.delay, os._exit, args=(17,)).start()
