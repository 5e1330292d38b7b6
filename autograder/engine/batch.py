"""Batched calls: many calls of one student function in one request, each its own call.

``student.map("orientation", [(p, q, r), ...])`` (:mod:`autograder.engine.proxy`)
sends the calls in one ``map`` request; the worker answers each with a frame of
its own (:func:`autograder.worker.loop.serve_map`) and ends with ``map-done``.
What a crossing costs is paid once per batch instead of once per call, and
nothing else changes. Each call keeps:

* its own CPU limit and wall-clock backstop, counted from when the grader read
  the answer before it (the worker starts the next call meanwhile, so the time
  between two answers is the next call's);
* its own verdict: a value, or the error a single call would have raised, at its
  position in the batch;
* the frame limit, per answer;
* the rules for calls that fail: a call that runs out of time or ends the worker
  stops the batch there; the worker is started again and the calls not answered
  yet are sent again, each refused first if a single call would be (an input at
  least as large as one that ran out of time, a function that crashed twice), so
  a batch gives the verdicts the same calls one by one would.

The worker is untrusted: an answer out of order, a second answer to one call, an
answer tagged with another batch, a frame after the last answer other than
``map-done``, or any other request while a batch runs is the student's
:class:`~autograder.errors.ProtocolViolation` (the batch's number and order are
no secret, so they only keep honest frames apart; forging an answer gains
nothing, as the answer is what the student's own code computed).

A check may stop reading a batch early (its first failure ends it). The answers
still in flight are then read before the next request (:meth:`Batch.drain`) and
kept: a check that goes on reading gets them; what they say about the function
(a time-out, a crash) counts against it only when a check reads it, and so does
the restart of the worker such a call stopped (``MAX_CALL_RESTARTS``).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Protocol

from autograder.engine.answers import call_value
from autograder.errors import CallTimeout, NotRun, ProtocolError, StudentError, WorkerCrashed

__all__ = ["MAX_BATCH", "Batch", "Outcome"]

#: most calls sent in one request; more are sent as the answers come
MAX_BATCH = 1024


@dataclass(frozen=True)
class Outcome:
    """One call of a batch: its value, or the error a single call would have raised."""

    value: Any = None
    error: StudentError | None = None
    #: what the call says about the function (a time-out, a crash), applied when a
    #: check reads the outcome
    failure: StudentError | None = None
    arguments: Any = None


class Process(Protocol):
    """What a batch needs of :class:`~autograder.engine.student_process.StudentProcess`."""

    _batch: Batch | None
    unread_stops: int

    def refusal(self, name: str, arguments: Any) -> NotRun | None: ...
    def note_failure(self, name: str, arguments: Any, error: StudentError, where: str) -> None: ...
    def ensure_worker(self, what: str) -> None: ...
    def worker(self) -> int | None: ...
    def stop_worker(self) -> None: ...
    def limited(self, what: str, timeout: float) -> AbstractContextManager[tuple[float, float]]: ...
    def send_batch(self, name: str, items: Sequence[list[Any]], limit: float,
                   wall_deadline: float) -> int: ...
    def receive_item(self, batch: int, index: int, limit: float,
                     wall_deadline: float) -> dict[str, Any]: ...
    def receive_done(self, batch: int, count: int, limit: float, wall_deadline: float) -> None: ...
    def call(self, name: str, args: Sequence[Any], kwargs: dict[str, Any], *,
             timeout: float, figures: bool = False) -> tuple[Any, list[Any]]: ...


#: where a batch's generator stands with nothing in flight (a drain stops there)
_IDLE = object()


class Batch:
    """An iterator over the :class:`Outcome` of each call ``name(*args)``, in order."""

    def __init__(self, process: Process, name: str, items: Sequence[list[Any]], *,
                 timeout: float, where: str) -> None:
        self._process = process
        self._name = name
        self._items = items
        self._timeout = timeout
        #: the check that made the batch, named when a call runs out of time
        self._where = where
        self._kept: deque[Outcome] = deque()
        self._steps = self._outcomes()
        self._in_flight = False
        self._finished = False
        self._number = 0

    def __iter__(self) -> Iterator[Outcome]:
        return self

    def __next__(self) -> Outcome:
        if self._kept:
            outcome = self._kept.popleft()
            if outcome.failure is not None:  # read now: its worker's stop counts from here
                self._process.unread_stops -= 1
        else:
            outcome = self._step()
        if outcome.failure is not None:
            self._process.note_failure(self._name, outcome.arguments, outcome.failure,
                                       self._where)
        return outcome

    def _step(self) -> Outcome:
        """The next outcome from the worker (sending calls when none is in flight)."""
        process = self._process
        if process._batch is not self:
            process.finish_batch()  # another batch's answers first: the worker sends them
        process._batch = None  # this batch's own calls (a fallback) must not drain it
        try:
            while True:
                step = self._advance()
                if step is None:
                    raise StopIteration
                if step is not _IDLE:
                    return step  # type: ignore[no-any-return]
        finally:
            if self._in_flight:
                process._batch = self

    def drain(self) -> None:
        """Read and keep the answers in flight, without what they say about the function.

        Called before the worker gets another request. Stops where nothing is in
        flight: at the end of what was sent, or at a call that stopped the worker;
        the calls not sent yet are sent when a check asks for them.
        """
        while self._in_flight:
            step = self._advance()
            if step is None:
                return
            if step is not _IDLE:
                if step.failure is not None:  # the call stopped the worker; not read yet
                    self._process.unread_stops += 1
                self._kept.append(step)

    def _advance(self) -> Any:
        """The next step of :meth:`_outcomes` (an outcome or ``_IDLE``); None once it ended."""
        if self._finished:
            return None
        try:
            return next(self._steps)
        except StopIteration:
            self._finished = True
            return None

    def _outcomes(self) -> Iterator[Any]:
        process, name, what = self._process, self._name, f"{self._name}()"
        k = 0
        while k < len(self._items):
            self._in_flight = False
            yield _IDLE
            refused = process.refusal(name, self._items[k])
            if refused is not None:
                yield Outcome(error=refused)
                k += 1
                continue
            try:
                process.ensure_worker(what)
            except StudentError as exc:
                yield Outcome(error=exc)
                k += 1
                continue
            refusals = {j: process.refusal(name, self._items[j])
                        for j in range(k, min(k + MAX_BATCH, len(self._items)))}
            k = yield from self._run_group(k, refusals)

    def _run_group(self, start: int, refusals: dict[int, NotRun | None]) -> Iterator[Any]:
        """Send the calls from ``start`` that are not refused and yield the outcomes from
        ``start`` on; return the index of the first call not answered yet."""
        process, name, what = self._process, self._name, f"{self._name}()"
        group = [j for j, refused in refusals.items() if refused is None]
        sent: list[int] = []
        worker = process.worker()
        batch = 0
        k = start
        for position, index in enumerate(group):
            while k < index:  # refused when the group was made, as a single call would be
                yield Outcome(error=refusals[k])
                k += 1
            if position and (process.worker() != worker or position >= len(sent)):
                return k  # the worker was replaced (or the rest never went): send again
            try:
                process.ensure_worker(what)  # the submission's budgets, between two calls
            except StudentError as exc:
                process.stop_worker()
                self._in_flight = False
                yield Outcome(error=exc)
                return k + 1
            arguments = self._items[index]
            try:
                with process.limited(what, self._timeout) as (limit, deadline):
                    if position == 0:
                        sent = self._send(group, limit, deadline)
                        if not sent:  # one call alone does not fit a frame
                            break
                        self._in_flight = True
                        batch = self._number
                    answer = process.receive_item(batch, position, limit, deadline)
                    if position == len(sent) - 1:
                        process.receive_done(batch, len(sent), limit, deadline)
                        self._in_flight = False
                value = call_value(name, answer)
            except (CallTimeout, WorkerCrashed) as exc:
                self._in_flight = False
                yield Outcome(error=exc, failure=exc, arguments=arguments)
                return index + 1
            except StudentError as exc:
                if process.worker() is None:  # a violation or an unreadable frame stopped it
                    self._in_flight = False
                    yield Outcome(error=exc)
                    return index + 1
                yield Outcome(error=exc)
            else:
                yield Outcome(value=value)
            k = index + 1
        else:
            return k
        # A single call whose arguments do not fit one frame: as a single call, which says so.
        try:
            value, _ = process.call(name, self._items[index], {}, timeout=self._timeout)
        except StudentError as exc:
            yield Outcome(error=exc)
        else:
            yield Outcome(value=value)
        return index + 1

    def _send(self, group: list[int], limit: float, deadline: float) -> list[int]:
        """Send as many calls of ``group`` as fit one frame; the indices sent ([] when
        not even one fits)."""
        count = len(group)
        while count:
            try:
                self._number = self._process.send_batch(
                    self._name, [self._items[j] for j in group[:count]], limit, deadline)
            except ProtocolError:  # raised before anything was sent
                count //= 2
                continue
            return group[:count]
        return []
