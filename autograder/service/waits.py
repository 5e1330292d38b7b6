"""Requests waiting for an attempt to be graded, woken when a grading process records it.

``GET /api/submissions/ID?wait=S`` answers once the attempt is graded (or failed), or
after ``S`` seconds, whichever comes first, so ``autograder submit`` and the live
status page learn the score as soon as it is there without asking again and again.
A grading process puts the id of every submission it records on the pool's queue
(:class:`~autograder.service.pool.GradingPool`); a thread of the web process reads
that queue and wakes the requests waiting for it (:meth:`Waits.finished`). A waiting
request holds no database session and no thread: it awaits an event, and looks at
the database again when woken, and at least every :data:`RECHECK` seconds (a
result recorded by another service sharing the database sends no word here).

Why by hand: the graders are processes of the standard library's
``multiprocessing``, not of the web server's event loop; the few lines that carry an
id from one to the other are all it takes.
"""

from __future__ import annotations

import asyncio
import threading
from typing import Any

#: the longest a request may wait, in seconds (a longer ``wait`` is refused with 422)
MAX_WAIT = 60.0
#: a waiting request looks at the database at least this often, woken or not
RECHECK = 1.0


class Waits:
    """The requests waiting per submission id; :meth:`finished` may be called from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._waiting: dict[int, set[tuple[asyncio.AbstractEventLoop, asyncio.Event]]] = {}

    def finished(self, sub_id: int) -> None:
        """Wake every request waiting for ``sub_id``."""
        with self._lock:
            waiting = list(self._waiting.get(sub_id, ()))
        for loop, event in waiting:
            try:
                loop.call_soon_threadsafe(event.set)
            except RuntimeError:  # its loop has closed: nobody is waiting any more
                pass

    async def wait(self, sub_id: int, seconds: float) -> None:
        """Return after ``seconds``, or sooner when :meth:`finished` is called for ``sub_id``."""
        entry = (asyncio.get_running_loop(), asyncio.Event())
        with self._lock:
            self._waiting.setdefault(sub_id, set()).add(entry)
        try:
            await asyncio.wait_for(entry[1].wait(), max(0.0, seconds))
        except asyncio.TimeoutError:
            pass
        finally:
            with self._lock:
                waiting = self._waiting.get(sub_id)
                if waiting is not None:
                    waiting.discard(entry)
                    if not waiting:
                        del self._waiting[sub_id]

    def relay(self, queue: Any) -> threading.Thread:
        """Start a thread that reads submission ids from ``queue`` (None ends it) and wakes
        their waiting requests."""
        def run() -> None:
            while True:
                try:
                    sub_id = queue.get()
                except (EOFError, OSError):  # the pool is gone
                    return
                if sub_id is None:
                    return
                if type(sub_id) is int:
                    self.finished(sub_id)

        thread = threading.Thread(target=run, daemon=True, name="graded-relay")
        thread.start()
        return thread
