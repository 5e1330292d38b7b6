"""Trusted side of the boundary: one submission's sandboxed process, from its cells to its calls.

A :class:`StudentProcess` asks a :class:`~autograder.engine.slot.GradingSlot` for a
fresh sandboxed child per submission, waits for the notebook to run, and then sends
calls with a time limit each. The grader kills the child's whole process group on
any timeout (see :mod:`autograder.sandbox.reaper`); it never waits on student code
without a deadline, whether it reads from the child or writes to it (a child that
never reads fills the socket: every send waits under the same CPU limit and
wall-clock backstop as a receive).

The child is untrusted, so the grader holds it to the protocol: at each point only
the frame the protocol allows there is accepted (``started`` or ``sandbox-broken``
first, then ``cell`` announcements in order and ``ready``; after a request, its
answer or a callback request, sent only once the child has read everything the
grader sent). Anything else is the student's :class:`~autograder.errors.ProtocolViolation`:
the worker is stopped as if it had crashed, and the rules for a crashed worker apply.
"""

from __future__ import annotations

import fcntl
import json
import os
import select
import shutil
import socket
import tempfile
import termios
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

import numpy as np

from autograder.boundary import codec, frames
from autograder.boundary.limits import MAX_CELLS
from autograder.engine.answers import call_value, describe, is_answer, shown
from autograder.engine.batch import Batch
from autograder.engine.slot import GradingSlot
from autograder.errors import (
    CallTimeout,
    EngineError,
    NotebookError,
    NotRun,
    ProtocolError,
    ProtocolViolation,
    StudentError,
    UnsupportedValue,
    WorkerCrashed,
)
from autograder.sandbox.policy import IsolationPolicy
from autograder.sandbox.cputime import CpuClock, slot_clock
from autograder.sandbox.reaper import child_pidfd, kill_child, sweep_slot

#: how many cells that hang or kill the worker are skipped before giving up on a notebook
MAX_RESTARTS = 2
#: how many times a submission's worker is restarted after a call hung or killed it
MAX_CALL_RESTARTS = 8
#: after this many crashes, a function is not called again for this submission
MAX_STRIKES = 2
#: time limits count CPU seconds; code that sleeps or blocks is stopped by a wall-clock
#: backstop of ``WALL_FACTOR * limit + WALL_SLACK`` seconds, generous enough that a
#: loaded machine never reaches it with code that computes
WALL_FACTOR = 4.0
WALL_SLACK = 15.0
#: shortest wait between two readings of the CPU clock while a call runs
MIN_POLL = 0.05
#: cores this machine has: how fast a child's CPU time can grow against wall time
_CORES = os.cpu_count() or 1


def wall_backstop(cpu_limit: float) -> float:
    """Wall-clock seconds after which code that is not computing is stopped."""
    return WALL_FACTOR * cpu_limit + WALL_SLACK


def wall_limit(notebook_timeout: float, cpu_budget: float) -> float:
    """The most wall-clock seconds one submission's worker can take, every backstop reached.

    The notebook runs up to ``MAX_RESTARTS + 1`` times before the first call; calls
    start until the submission's wall budget (``wall_backstop(cpu_budget)`` since the
    start) is spent, and the last one may take as long again, a restart of the
    notebook included. What the checks do on the trusted side comes on top.
    """
    return (MAX_RESTARTS + 2) * wall_backstop(notebook_timeout) + 2 * wall_backstop(cpu_budget)


def payload_size(value: Any, _depth: int = 0) -> int:
    """How many numbers a call's arguments hold: the "input size" of a call."""
    if _depth > 32:
        return 1
    if isinstance(value, np.ndarray):
        return int(value.size)
    if isinstance(value, dict):
        return sum(payload_size(v, _depth + 1) for v in value.values())
    if isinstance(value, (list, tuple)):
        return sum(payload_size(v, _depth + 1) for v in value)
    return 1


@dataclass(frozen=True)
class CellRun:
    """How one code cell ended, as reported by the worker (plain data)."""

    index: int
    ok: bool
    seconds: float
    ename: str = ""
    evalue: str = ""
    traceback: str = ""


@dataclass(frozen=True)
class NotebookRun:
    """What running the notebook produced, before any check is run."""

    cells: tuple[CellRun, ...]
    stdout: str
    functions: tuple[str, ...]
    seconds: float
    timed_out_cells: tuple[int, ...] = ()
    crashed_cells: tuple[int, ...] = ()
    crashed: bool = False
    notes: tuple[str, ...] = ()
    cpu_seconds: float = 0.0
    #: what the student's code wrote to the grader's connection, if it did (see ProtocolViolation)
    violation: str = ""
    #: the index of the first hidden test cell whose source the worker was given: the
    #: cells from it on ran where student code could have read a hidden test, so their
    #: output is not in ``stdout`` and their reports are for scoring only (None: no
    #: hidden test ran)
    hidden_from: int | None = None


#: the most characters of captured output the grader keeps from the worker
OUTPUT_CAP = 1 << 20
#: the most cell reports kept (each holds at most a 20,000-character traceback)
MAX_CELL_REPORTS = 200
#: names of the functions a notebook defined that the grader keeps from its report
MAX_FUNCTION_NAMES = 10_000


def check_cell_count(count: int) -> None:
    """Refuse a notebook of more than :data:`~autograder.boundary.limits.MAX_CELLS` code cells.

    Raises :class:`~autograder.errors.NotebookError` (``kind="too-many-cells"``): the
    notebook is not run at all, and the message says so.
    """
    if count > MAX_CELLS:
        raise NotebookError(
            f"it has {count:,} code cells, and the grader runs notebooks of at most "
            f"{MAX_CELLS:,}. None of its code was run. Merge cells (or remove empty and "
            "generated ones) and submit again.", kind="too-many-cells")


class _Violation(Exception):
    """A frame the protocol does not allow at this point (raised inside this module only)."""


def _unread_bytes(sock: socket.socket) -> int:
    """Bytes the grader sent that the child has not read yet (SIOCOUTQ of a UNIX socket)."""
    raw = fcntl.ioctl(sock.fileno(), termios.TIOCOUTQ, b"\0\0\0\0")
    return int.from_bytes(raw, "little", signed=True)


def _cell_report(data: Any) -> CellRun:
    """A :class:`CellRun` from the worker's plain data, every field checked."""
    return CellRun(index=int(data["index"]), ok=bool(data["ok"]),
                      seconds=float(data["seconds"]), ename=str(data.get("ename", ""))[:200],
                      evalue=str(data.get("evalue", ""))[:2000],
                      traceback=str(data.get("traceback", ""))[:20_000])


@dataclass
class StudentProcess:
    """One submission's sandboxed worker: run its cells, then answer calls.

    Time limits are CPU seconds of the child's session (see :mod:`autograder.sandbox.cputime`),
    with a wall-clock backstop for code that sleeps or blocks, so a verdict never
    depends on how busy the machine is.
    """

    slot: GradingSlot
    cells: Sequence[tuple[int, str]]
    data_files: Sequence[tuple[Path, str]]
    policy: IsolationPolicy
    notebook_timeout: float
    exclude: Sequence[Path] = ()
    #: CPU seconds the whole submission may use (notebook, restarts and calls)
    cpu_budget: float | None = None
    #: the assignment's forbidden libraries, enforced in the worker at run time:
    #: ``{"names": [...], "internal_use": [...], "reason": "..."}``
    forbid: dict[str, Any] = field(default_factory=dict)
    #: an otter assignment's public tests, for ``grader.check`` in the worker
    #: (:mod:`autograder.worker.otter_stub`); None for other assignments
    otter: dict[str, Any] | None = None
    #: sources of the hidden test cells, by index: left out of the start request and
    #: sent only when the worker reaches the cell (see :meth:`_give_source`)
    hidden_sources: dict[int, str] = field(default_factory=dict)
    restarts: int = 0
    #: workers stopped by a call of a drained batch (see :meth:`Batch.drain`) that no
    #: check has read yet: their restarts count against ``MAX_CALL_RESTARTS`` only
    #: once a check reads the call, as the call's time-out or crash does
    unread_stops: int = 0
    skip: dict[int, str] = field(default_factory=dict)
    #: per function: how often a call crashed the worker, and the last such error
    strikes: dict[str, tuple[int, StudentError]] = field(default_factory=dict)
    #: per function: the smallest input size on which it ran out of time, and where
    timed_out: dict[str, tuple[int, str]] = field(default_factory=dict)
    #: answers a callback request from the worker (set by whoever passes callables)
    on_callback: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    #: the check being run, for "not run, because ... on <check>" messages
    current_check: str = ""
    cpu_seconds: float = 0.0
    #: the last protocol violation of the student's code, said again to every later call
    violation: str = ""
    _pid: int | None = None
    #: names the child itself; every signal to it goes through this (see kill_child)
    _pidfd: int | None = None
    _sock: socket.socket | None = None
    _workdir: Path | None = None
    _clock: CpuClock | None = None
    _started_at: float | None = None
    #: this run's hidden test cells not yet given to the worker, in running order
    _pending: list[int] = field(default_factory=list)
    #: set when the first hidden test is given: (its index, the reports and output before it)
    _before: tuple[int, list[CellRun], str] | None = None
    report: NotebookRun | None = None
    #: a batch whose worker is still sending answers (see :meth:`finish_batch`)
    _batch: Batch | None = None
    #: batches sent so far: each is numbered, and its answers carry the number
    _batches: int = 0
    #: workers started for this submission
    _spawns: int = 0
    #: a child forked by :meth:`launch` that :meth:`start` has not used yet
    _launched: bool = False

    # -- lifecycle -------------------------------------------------------
    def launch(self) -> None:
        """Fork the child now; :meth:`start` then gives it the cells.

        The child enters its sandbox meanwhile, and its entry into the slot's cgroup
        waits some 7 ms for the kernel (an RCU grace period) while using no CPU, so
        the grader's own work on the submission (the static scan) can fill that wait.
        The child learns nothing of the submission before :meth:`start`: the spawn
        request holds no cells. Before :meth:`start` only, and at most once.
        """
        if self._spawns == 0:
            self._spawn()
            self._launched = True

    def start(self) -> NotebookRun:
        """Run the notebook; a cell that hangs or kills the worker is skipped and the rest re-run."""
        begin = time.perf_counter()
        self._started_at = time.monotonic()
        notes: list[str] = []
        cells: list[CellRun] = []
        stdout, functions = "", []
        while True:
            status, cell, payload = self._run_once(notes)
            if status == "ready":
                cells, stdout, functions = payload
                break
            if cell is None or len(self.skip) >= MAX_RESTARTS + 1:
                self._kill()
                self._pid = None
                if cell is not None:
                    self.skip[cell] = status
                break
            self.skip[cell] = status
        hidden_from = None
        if self._before is not None and self._pid is not None:
            # Only what the worker said before a hidden test reached it is shown.
            hidden_from, earlier, stdout = self._before
            cells = ([c for c in earlier if c.index < hidden_from]
                     + [c for c in cells if c.index >= hidden_from])
        self.report = NotebookRun(
            cells=tuple(cells), stdout=stdout,
            functions=tuple(functions), seconds=time.perf_counter() - begin,
            timed_out_cells=tuple(sorted(i for i, s in self.skip.items() if s == "timeout")),
            crashed_cells=tuple(sorted(i for i, s in self.skip.items() if s == "crash")),
            crashed=self._pid is None, notes=tuple(notes), cpu_seconds=self.cpu_seconds,
            violation=self.violation, hidden_from=hidden_from)
        return self.report

    def _run_once(self, notes: list[str]) -> tuple[str, int | None, Any]:
        """Run the cells once: ("ready", None, data), or ("timeout"|"crash", cell, None)."""
        if self._launched:  # forked ahead by launch(), with nothing skipped yet
            self._launched = False
        else:
            self._spawn()
        started = False
        current: int | None = None
        #: the cells the child runs, in order: it announces each before running it
        order = [i for i, _ in self.cells if i not in self.skip]
        announced = 0
        assert self._clock is not None
        spent: float | None = None
        wall_deadline = time.monotonic() + wall_backstop(self.notebook_timeout)
        try:
            while True:
                try:
                    message = self._await(self.notebook_timeout, wall_deadline)
                except TimeoutError:
                    spent = self._clock.used()
                    self._kill()
                    return "timeout", current, None
                except (EOFError, OSError, ProtocolError) as exc:
                    self._kill()
                    if not started:  # the engine's own set-up failed, not the student
                        raise EngineError(
                            "the sandboxed worker stopped before running any cell "
                            f"({type(exc).__name__}); see the grader's log") from None
                    return "crash", current, None
                if not started:
                    self._set_up(message, notes)
                    self._give_cells(wall_deadline)
                    started = True
                    continue
                try:  # from here on the child runs student code: it is held to the protocol
                    op = message.get("op") if isinstance(message, dict) else None
                    if op == "cell":
                        if announced >= len(order) or message.get("index") != order[announced]:
                            raise _Violation(f"it announced cell {shown(message.get('index'))} "
                                             "out of turn")
                        current, announced = order[announced], announced + 1
                    elif op == "need-source":
                        self._give_source(message, current, wall_deadline)
                    elif op == "ready":
                        if announced != len(order):
                            raise _Violation("it reported the notebook finished before its "
                                             "last cell ran")
                        reports = [_cell_report(c) for c in message["cells"][:MAX_CELL_REPORTS]]
                        return "ready", None, (reports,
                                               str(message.get("stdout", ""))[:OUTPUT_CAP],
                                               [str(f)[:200] for f in message.get("functions", [])[:MAX_FUNCTION_NAMES]])
                    else:
                        raise _Violation(f"it sent {describe(message)} while the notebook ran")
                except (KeyError, TypeError, ValueError):  # a malformed "ready"
                    self._violated(f"cell {shown(current)}", "it sent a malformed report")
                    return "crash", current, None
                except _Violation as exc:
                    self._violated(f"cell {shown(current)}", str(exc))
                    return "crash", current, None
                except TimeoutError:  # it did not read the source it asked for
                    spent = self._clock.used()
                    self._kill()
                    return "timeout", current, None
                except OSError:
                    self._kill()
                    return "crash", current, None
        finally:
            self.cpu_seconds += spent if spent is not None else self._clock.own()

    def _give_source(self, message: dict[str, Any], current: int | None,
                     wall_deadline: float) -> None:
        """Send the source of the hidden test cell the worker has reached.

        Answered only for the next hidden test cell of this run, in running order and
        once each, and only for the cell the worker announced; any other request is
        the student's code speaking for the worker (:class:`_Violation`). The first
        answer also fixes what the feedback may show: the reports and output sent with
        the request, from before any hidden test was in the process.
        """
        index = message.get("index")
        if not self._pending or index != self._pending[0] or index != current:
            raise _Violation(f"it asked for the source of cell {shown(index)}, which is "
                             "not the hidden test cell it is at")
        if self._before is None:
            reports = [_cell_report(c) for c in message["cells"][:MAX_CELL_REPORTS]]
            self._before = (index, reports, str(message["stdout"])[:OUTPUT_CAP])
        self._pending.pop(0)
        self._send({"op": "source", "index": index, "source": self.hidden_sources[index]},
                   self.notebook_timeout, wall_deadline)

    def _set_up(self, message: Any, notes: list[str]) -> None:
        """The child's first frame, sent before any student code ran: ``started``, or the
        sandbox's own finding that a file student code needs is unreadable.

        Only here is ``sandbox-broken`` believed: the child has run nothing of the
        student's yet. Later, the same frame is the student's protocol violation.
        """
        op = message.get("op") if isinstance(message, dict) else None
        if op == "started":
            listed = message.get("notes", [])
            notes[:] = [str(n)[:500] for n in (listed if isinstance(listed, list) else [])][:64]
            return
        self._kill()
        if op == "sandbox-broken":
            raise EngineError(
                "the sandbox is incomplete: the worker cannot read "
                f"{str(message.get('path', '?'))[:300]} "
                f"({str(message.get('error', ''))[:200]}). Grading stopped, so no "
                "student gets a wrong zero; report this with the grader's "
                "install layout (where Python and its packages live).")
        raise EngineError(f"the sandboxed worker sent {describe(message)} before starting; "
                          "see the grader's log")

    def _give_cells(self, wall_deadline: float) -> None:
        """Send this run's cells to the child, which has entered its sandbox and run
        nothing yet.

        To the child itself, never in the spawn request: the warm parent would keep them
        in its freed memory, which every later child of the slot inherits. One string,
        not a list: a notebook of many tiny cells must not reach the protocol's item
        limit. A hidden test cell goes without its source (null): see _give_source.
        """
        cells = json.dumps([[i, None if i in self.hidden_sources else s]
                            for i, s in self.cells if i not in self.skip])
        try:
            self._send({"op": "cells", "cells_json": cells}, self.notebook_timeout, wall_deadline)
        except (TimeoutError, OSError) as exc:
            self._kill()
            raise EngineError("the sandboxed worker did not take the notebook's cells "
                              f"({type(exc).__name__}); see the grader's log") from None

    def _violated(self, where: str, detail: str) -> None:
        """Stop the child for a protocol violation at ``where`` and remember it."""
        self._kill()
        if self._before is not None:  # a hidden test was in the child: what it sent could hold it
            detail = "it sent a frame out of turn (not shown: a hidden test had run)"
        self.violation = (f"{where} broke the grader's protocol: {detail}. Your code must not "
                          "read or write the worker's connection to the grader (a file "
                          "descriptor of the process), so the worker was stopped")
        if self.report is not None:  # a call's violation: the run's report says it too
            self.report = replace(self.report, violation=self.violation)

    def _spawn(self) -> None:
        self._kill()
        self._spawns += 1
        self._workdir = Path(tempfile.mkdtemp(prefix="submission-", dir=self.slot.work_root))
        for source, relative in self.data_files:
            target = self._workdir / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
        request = {
            "op": "spawn", "workdir": str(self._workdir), "slot": self.slot.slot,
            "policy": _policy_to_wire(self.policy), "forbid": self.forbid,
            "exclude": [str(p) for p in self.exclude],
        }
        # No cells here: the child gets them once it is sandboxed (_give_cells).
        self._pending = [i for i, _ in self.cells if i in self.hidden_sources and i not in self.skip]
        self._before = None
        if self.otter is not None:
            request["otter"] = self.otter
        if os.listdir(self.slot.work_root) == [self._workdir.name]:
            # The warm parent's one ruleset may then serve this child: it lets the child
            # change files anywhere in the work root, which holds nothing but its own
            # folder (a leftover that could not be removed makes the child build its own).
            request["workroot"] = str(self.slot.work_root)
        self._pid, self._sock = self.slot.spawn(request)
        self._pidfd = child_pidfd(self._pid, self.slot.warm_parent)
        self._clock = slot_clock(self._pid, self.policy, self.slot.slot, self.slot.warm_parent)
        self._clock.start()  # the child's sandbox entry counts, whenever its cells come

    def _await(self, cpu_limit: float, wall_deadline: float) -> Any:
        """The child's next message; TimeoutError once it used ``cpu_limit`` CPU seconds
        (since the clock's start) or the wall-clock backstop passed."""
        if self._sock is None or self._clock is None:
            raise EOFError("no worker")
        wall_left = self._wait_for(self._sock, cpu_limit, wall_deadline, write=False)
        # A frame has started: the child may still stall inside it, so the
        # wall-clock backstop bounds the rest of the read.
        return frames.recv_message(self._sock, timeout=max(wall_left, 1.0))

    def _send(self, message: dict[str, Any], cpu_limit: float, wall_deadline: float) -> None:
        """Send ``message`` to the child under the same limits as :meth:`_await`.

        A child that does not read fills the socket; the send then waits for room
        only while the child is within its CPU limit and the wall-clock backstop.
        """
        if self._sock is None or self._clock is None:
            raise EOFError("no worker")
        frames.send_message(self._sock, message, wait=lambda sock: self._wait_for(
            sock, cpu_limit, wall_deadline, write=True))

    def _wait_for(self, sock: socket.socket, cpu_limit: float, wall_deadline: float, *,
                  write: bool) -> float:
        """Wait until ``sock`` is readable (or writable); return the wall seconds left.

        TimeoutError once the child used ``cpu_limit`` CPU seconds (since the clock's
        start) or the wall-clock backstop passed.
        """
        assert self._clock is not None
        used = 0.0
        while True:
            # CPU time cannot grow faster than wall time times the cores the child may use.
            cpu_wait = max(MIN_POLL, (cpu_limit - used) / _CORES)
            wall_left = wall_deadline - time.monotonic()
            if wall_left < cpu_wait + 1.0:
                # The backstop is pushed back by the time the child sat waiting for a CPU,
                # so a loaded machine does not make computing code look like waiting code.
                # Read only near the backstop: until then the wait below is cpu_wait.
                wall_left += self._clock.queued()
            if used >= cpu_limit or wall_left <= 0:
                raise TimeoutError
            wait = min(wall_left, cpu_wait)
            readable, writable, _ = select.select([] if write else [sock],
                                                  [sock] if write else [], [], wait)
            if readable or writable:
                return wall_left
            used = self._clock.used()

    def _kill(self) -> None:
        if self._pid is not None:
            kill_child(self._pid, self._pidfd)
            sweep_slot(self.policy, self.slot.slot, self.slot.warm_parent,
                       child=None if self._pidfd is None else (self._pid, self._pidfd))
            if self._pidfd is not None:
                os.close(self._pidfd)
            # Forgotten once killed: a later _kill (the next spawn, close) must not
            # signal a number the warm parent has reaped and the kernel may reuse.
            self._pid = self._pidfd = None
        if self._clock is not None:
            self._clock.close()
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None

    def close(self) -> None:
        self._batch = None  # answers still in flight are not needed: the worker is stopped
        if self._sock is not None:
            try:  # never waited for: a child that does not read is killed just below
                frames.send_message(self._sock, {"op": "bye"}, wait=_give_up)
            except OSError:  # TimeoutError included
                pass
        self._kill()
        self._pid = None

    # -- calls -------------------------------------------------------------
    def _budget_left(self) -> float:
        return float("inf") if self.cpu_budget is None else self.cpu_budget - self.cpu_seconds

    def _wall_budget_spent(self) -> bool:
        """Past the submission's wall-clock budget: code that mostly sleeps or waits."""
        if self.cpu_budget is None or self._started_at is None:
            return False
        return time.monotonic() - self._started_at > wall_backstop(self.cpu_budget)

    def request(self, message: dict[str, Any], *, timeout: float, what: str) -> dict[str, Any]:
        """Send ``message`` and return the answer, or raise a :class:`StudentError`.

        ``timeout`` is in CPU seconds. Callback requests from the worker (a student
        function calling a function a check passed) are answered in between.
        """
        self.finish_batch()
        self.ensure_worker(what)
        with self.limited(what, timeout) as (limit, wall_deadline):
            self._send(message, limit, wall_deadline)
            return self._exchange(limit, wall_deadline)
        raise AssertionError("unreachable")  # limited() raises or the block returned

    @contextmanager
    def limited(self, what: str, timeout: float) -> Iterator[tuple[float, float]]:
        """One call's limits: yield ``(CPU limit, wall deadline)`` and turn what goes
        wrong inside into the student's error.

        The limit is ``timeout`` CPU seconds, or what is left of the submission's
        budget; the clock counts from the end of the last call (or batch item). A time
        limit, a violation, an unreadable frame or a lost worker stops the worker and
        raises :class:`CallTimeout`, :class:`ProtocolViolation`,
        :class:`UnsupportedValue` or :class:`WorkerCrashed`; the CPU time used is
        added to the submission's in every case.
        """
        assert self._sock is not None and self._clock is not None
        limit = min(timeout, self._budget_left())
        spent: float | None = None
        self._clock.start()
        wall_deadline = time.monotonic() + wall_backstop(limit)
        try:
            yield limit, wall_deadline
        except TimeoutError:
            used = spent = self._clock.used()
            self._kill()
            if used >= limit:
                raise CallTimeout(
                    f"{what} used more than {limit:g} s of CPU time; look for a loop that "
                    "never ends or work that grows too fast with the input size.") from None
            raise CallTimeout(
                f"{what} did not return within {wall_backstop(limit):g} s although it used "
                f"only {used:.1f} s of CPU: it was waiting (sleep, input, a lock, a pipe).") from None
        except _Violation as exc:
            self._violated(what, str(exc))
            raise ProtocolViolation(f"{self.violation}.") from None
        except ProtocolError as exc:
            self._kill()
            raise UnsupportedValue(
                f"{what} returned a value the grader cannot read ({exc}); return a number, "
                "a list or tuple of numbers, or a numpy array of a sensible size.") from None
        except (EOFError, OSError) as exc:
            self._kill()
            raise WorkerCrashed(
                f"{what} ended the worker process (it exited, was killed by a memory or "
                f"CPU limit, or crashed): {type(exc).__name__}.") from None
        finally:
            if self._clock is not None:
                self.cpu_seconds += spent if spent is not None else self._clock.own()

    def ensure_worker(self, what: str) -> None:
        """Raise unless the submission may still make a call; restart its worker if needed."""
        if self._wall_budget_spent():
            raise NotRun(f"{what} was not run: your submission used its whole time budget "
                         f"({wall_backstop(self.cpu_budget or 0):g} s), mostly waiting rather "
                         "than computing (sleep, input, locks).")
        if self._budget_left() <= 0:
            raise NotRun(f"{what} was not run: your submission used its whole time budget "
                         f"({self.cpu_budget:g} s of CPU) on earlier cells and calls.")
        if self._sock is not None:
            return
        counted = self.restarts - self.unread_stops
        if self.report is None or self.report.crashed or counted >= MAX_CALL_RESTARTS:
            if self.violation:
                raise ProtocolViolation(f"{what} could not run: {self.violation}.")
            raise WorkerCrashed(
                f"{what} could not run: your notebook's worker stopped earlier "
                "(a time limit, a memory limit, or code that ended the process).")
        self.restarts += 1
        status, _, _ = self._run_once([])
        if status != "ready":
            self._kill()
            raise WorkerCrashed(f"{what} could not run: restarting your notebook failed.")

    def _exchange(self, limit: float, wall_deadline: float) -> dict[str, Any]:
        """The answer to the request just sent; the child's callback requests are
        answered meanwhile. Anything else it sends is a :class:`_Violation`."""
        assert self._sock is not None
        while True:
            message = self._await(limit, wall_deadline)
            if _unread_bytes(self._sock):
                # The worker reads all the grader sent before it writes again (a callback
                # waits for its answer): a frame now was written by the student's code.
                raise _Violation("it wrote to the grader's connection without reading what "
                                 "the grader had sent")
            if is_answer(message):
                return message  # type: ignore[no-any-return]
            if not (isinstance(message, dict) and message.get("op") == "callback"):
                raise _Violation(f"it sent {describe(message)} where the grader expected "
                                 "an answer")
            reply = (self.on_callback(message) if self.on_callback is not None else
                     {"op": "callback-result", "ok": False, "error": "no callbacks"})
            if "tally" in message:  # counts of functions run in the child: not answered
                continue
            self._send(reply, limit, wall_deadline)

    def call(self, name: str, args: Sequence[Any], kwargs: dict[str, Any], *,
             timeout: float, figures: bool = False) -> tuple[Any, list[Any]]:
        """Call the student's ``name(*args, **kwargs)``; return (value, figures)."""
        what = f"{name}()"
        refused = self.refusal(name, [list(args), kwargs])
        if refused is not None:
            raise refused
        try:
            answer = self.request({"op": "call", "name": name, "args": list(args),
                                   "kwargs": kwargs, "figures": figures},
                                  timeout=timeout, what=what)
        except (CallTimeout, WorkerCrashed) as exc:
            self.note_failure(name, [list(args), kwargs], exc, self.current_check)
            raise
        return call_value(name, answer), list(answer.get("figures", []))

    def refusal(self, name: str, arguments: Any) -> NotRun | None:
        """Why ``name`` is not called on ``arguments`` at all, if it is not: it ran out of
        time on an input at least as small, or crashed the worker too often."""
        what = f"{name}()"
        # Counted only when a time-out needs it: a recursive walk of every argument
        # cost the grader about 2% of its time on the hull checks.
        smallest = self.timed_out.get(name)
        if smallest is not None and payload_size(arguments) >= smallest[0]:
            return NotRun(f"{what} was not run on this input, because `{name}` ran out of "
                          f"time on {smallest[1]}, an input at least as small.")
        count, earlier = self.strikes.get(name, (0, None))
        if earlier is not None and count >= MAX_STRIKES:
            # A function that crashed twice would cost a restart on every remaining
            # check, starving the other functions' checks.
            return NotRun(f"{what} was not run: {earlier} (it did so {count} times, so it "
                          "was not called again)")
        return None

    def note_failure(self, name: str, arguments: Any, error: StudentError, where: str) -> None:
        """Remember a call of ``name`` that ran out of time or crashed the worker (see
        :meth:`refusal`); ``where`` names the check, for the message."""
        if isinstance(error, CallTimeout):
            size = payload_size(arguments)
            self.timed_out[name] = (min(size, self.timed_out.get(name, (size, ""))[0]),
                                    where or f"an input of size {size}")
        elif isinstance(error, WorkerCrashed):
            count, _ = self.strikes.get(name, (0, None))
            self.strikes[name] = (count + 1, error)

    def call_many(self, name: str, items: Sequence[list[Any]], *, timeout: float) -> Batch:
        """Calls ``name(*args)`` for each ``args`` in ``items``, sent as one batch; an
        iterator of one :class:`~autograder.engine.batch.Outcome` per item, in order
        (see :mod:`autograder.engine.batch`)."""
        self.finish_batch()
        return Batch(self, name, items, timeout=timeout, where=self.current_check)

    # -- the wire of a batch (see autograder.engine.batch) ----------------------
    def worker(self) -> int | None:
        """Which worker runs now (the count of workers started), None when none does: a
        batch's answers come only from the worker it was sent to."""
        return self._spawns if self._sock is not None else None

    def stop_worker(self) -> None:
        """Stop the worker; the next call starts the notebook again."""
        self._kill()

    def send_batch(self, name: str, items: Sequence[list[Any]], limit: float,
                   wall_deadline: float) -> int:
        """Send the calls of a batch (inside :meth:`limited`); return the batch's number.

        Raises ``ProtocolError`` before sending anything when the items do not fit in
        one frame (the caller sends fewer)."""
        assert self._sock is not None
        number = self._batches + 1
        tree, buffers = codec.encode({"op": "map", "batch": number, "name": name,
                                      "items": list(items)})
        frames.send_frame(self._sock, tree, buffers, wait=lambda sock: self._wait_for(
            sock, limit, wall_deadline, write=True))
        self._batches = number
        return number

    def receive_item(self, batch: int, index: int, limit: float,
                     wall_deadline: float) -> dict[str, Any]:
        """The answer to call ``index`` of ``batch`` (inside :meth:`limited`). Any other
        frame is the student's violation: an answer out of order, a second answer to
        one call, an answer to another batch, or any other request."""
        message = self._await(limit, wall_deadline)
        assert self._sock is not None
        if _unread_bytes(self._sock):
            raise _Violation("it wrote to the grader's connection before reading the batch")
        if not (isinstance(message, dict) and message.get("op") == "item"
                and message.get("batch") == batch and message.get("i") == index
                and "ok" in message):
            raise _Violation(f"it sent {describe(message)} where the grader expected the "
                             f"answer to call {index + 1} of a batch")
        return message

    def receive_done(self, batch: int, count: int, limit: float, wall_deadline: float) -> None:
        """The worker's word that ``batch`` ended after ``count`` answers; anything else
        (one answer more, say) is the student's violation."""
        message = self._await(limit, wall_deadline)
        if not (isinstance(message, dict) and message.get("op") == "map-done"
                and message.get("batch") == batch and message.get("count") == count):
            raise _Violation(f"it sent {describe(message)} after the last answer of a batch")

    def finish_batch(self) -> None:
        """Read the answers of a batch still in flight (see :meth:`Batch.drain`), so the
        worker can take a new request."""
        batch, self._batch = self._batch, None
        if batch is not None:
            batch.drain()

    def figures(self, *, timeout: float) -> list[Any]:
        answer = self.request({"op": "figures"}, timeout=timeout, what="drawing your figures")
        return list(answer.get("value", []))


def _give_up(sock: socket.socket) -> None:
    """A send's wait that does not wait (see :func:`autograder.boundary.frames.send_frame`)."""
    raise TimeoutError("the worker is not reading")


def _policy_to_wire(policy: IsolationPolicy) -> dict[str, Any]:
    data = asdict(policy)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in data.items()}
