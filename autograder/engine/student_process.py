"""Trusted side of the boundary: one submission's sandboxed process, from its cells to its calls.

A :class:`StudentProcess` asks a :class:`~autograder.engine.slot.GradingSlot` for a
fresh sandboxed child per submission, waits for the notebook to run, and then sends
calls with a time limit each. The grader kills the child's whole process group on
any timeout (see :mod:`autograder.sandbox.reaper`); it never waits on student code
without a deadline.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import socket
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from autograder.boundary import frames, values
from autograder.engine.slot import GradingSlot
from autograder.errors import (
    CallTimeout,
    EngineError,
    ForbiddenUse,
    MissingFunction,
    NotRun,
    ProtocolError,
    StudentError,
    StudentException,
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
    #: the index of the first hidden test cell whose source the worker was given: the
    #: cells from it on ran where student code could have read a hidden test, so their
    #: output is not in ``stdout`` and their reports are for scoring only (None: no
    #: hidden test ran)
    hidden_from: int | None = None


#: the most characters of captured output the grader keeps from the worker
OUTPUT_CAP = 1 << 20
#: the most cell reports kept (each holds at most a 20,000-character traceback)
MAX_CELL_REPORTS = 200


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

    # -- lifecycle -------------------------------------------------------
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
            # A cell skipped already cannot stop a run unless the student's code named it
            # (a forged "cell" frame): giving up then keeps the restarts finite.
            if cell is None or cell in self.skip or len(self.skip) >= MAX_RESTARTS + 1:
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
            hidden_from=hidden_from)
        return self.report

    def _run_once(self, notes: list[str]) -> tuple[str, int | None, Any]:
        """Run the cells once: ("ready", None, data), or ("timeout"|"crash", cell, None)."""
        self._spawn()
        started = False
        current: int | None = None
        assert self._clock is not None
        self._clock.start()
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
                if not isinstance(message, dict):
                    continue
                try:  # the child is untrusted: a malformed message counts as a crash
                    op = message.get("op")
                    if op == "sandbox-broken":
                        self._kill()
                        raise EngineError(
                            "the sandbox is incomplete: the worker cannot read "
                            f"{str(message.get('path', '?'))[:300]} "
                            f"({str(message.get('error', ''))[:200]}). Grading stopped, so no "
                            "student gets a wrong zero; report this with the grader's "
                            "install layout (where Python and its packages live).")
                    if op == "started":
                        started = True
                        notes[:] = [str(n)[:500] for n in message.get("notes", [])][:64]
                    elif op == "cell":
                        current = int(message["index"])
                    elif op == "need-source" and not self._give_source(message, current,
                                                                        wall_deadline):
                        self._kill()  # not the worker's request: the student's code speaking
                        return "crash", current, None
                    elif op == "ready":
                        reports = [_cell_report(c) for c in message["cells"][:MAX_CELL_REPORTS]]
                        return "ready", None, (reports,
                                               str(message.get("stdout", ""))[:OUTPUT_CAP],
                                               [str(f)[:200] for f in message.get("functions", [])])
                except (KeyError, TypeError, ValueError, OSError, ProtocolError):
                    self._kill()
                    return "crash", current, None
        finally:
            self.cpu_seconds += spent if spent is not None else self._clock.own()

    def _give_source(self, message: dict[str, Any], current: int | None,
                     wall_deadline: float) -> bool:
        """Send the source of the hidden test cell the worker has reached; False if the
        request breaks the protocol (then it came from the student's code).

        Answered only for the next hidden test cell of this run, in running order and
        once each, and only for the cell the worker announced. The first answer also
        fixes what the feedback may show: the reports and output that came with the
        request, from before any hidden test was in the process.
        """
        index = int(message["index"])
        if not self._pending or index != self._pending[0] or index != current:
            return False
        if self._before is None:
            reports = [_cell_report(c) for c in message["cells"][:MAX_CELL_REPORTS]]
            self._before = (index, reports, str(message["stdout"])[:OUTPUT_CAP])
        self._pending.pop(0)
        assert self._sock is not None
        # Bounded: a child that stopped reading must not hold the grader past its backstop.
        previous = self._sock.gettimeout()
        self._sock.settimeout(max(1.0, wall_deadline - time.monotonic()))
        try:
            frames.send_message(self._sock, {"op": "source", "index": index,
                                             "source": self.hidden_sources[index]})
        finally:
            self._sock.settimeout(previous)
        return True

    def _spawn(self) -> None:
        self._kill()
        self._workdir = Path(tempfile.mkdtemp(prefix="submission-", dir=self.slot.work_root))
        for source, relative in self.data_files:
            target = self._workdir / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
        request = {
            "op": "spawn", "workdir": str(self._workdir), "slot": self.slot.slot,
            "policy": _policy_to_wire(self.policy), "forbid": self.forbid,
            "exclude": [str(p) for p in self.exclude],
            # One string, not a list: a notebook of many tiny cells must not reach the
            # protocol's item limit (the worker parses it with json.loads).
            # A hidden test cell goes without its source (null): see _give_source.
            "cells_json": json.dumps([[i, None if i in self.hidden_sources else s]
                                      for i, s in self.cells if i not in self.skip]),
        }
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

    def _await(self, cpu_limit: float, wall_deadline: float) -> Any:
        """The child's next message; TimeoutError once it used ``cpu_limit`` CPU seconds
        (since the clock's start) or the wall-clock backstop passed."""
        if self._sock is None or self._clock is None:
            raise EOFError("no worker")
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
            readable, _, _ = select.select([self._sock], [], [], wait)
            if readable:
                # A frame has started: the child may still stall inside it, so the
                # wall-clock backstop bounds the rest of the read.
                return frames.recv_message(self._sock, timeout=max(wall_left, 1.0))
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
        if self._sock is not None:
            try:
                frames.send_message(self._sock, {"op": "bye"})
            except OSError:
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
        if self._wall_budget_spent():
            raise NotRun(f"{what} was not run: your submission used its whole time budget "
                         f"({wall_backstop(self.cpu_budget or 0):g} s), mostly waiting rather "
                         "than computing (sleep, input, locks).")
        if self._budget_left() <= 0:
            raise NotRun(f"{what} was not run: your submission used its whole time budget "
                         f"({self.cpu_budget:g} s of CPU) on earlier cells and calls.")
        if self._sock is None:
            if self.report is None or self.report.crashed or self.restarts >= MAX_CALL_RESTARTS:
                raise WorkerCrashed(
                    f"{what} could not run: your notebook's worker stopped earlier "
                    "(a time limit, a memory limit, or code that ended the process).")
            self.restarts += 1
            status, _, _ = self._run_once([])
            if status != "ready":
                self._kill()
                raise WorkerCrashed(f"{what} could not run: restarting your notebook failed.")
        assert self._sock is not None and self._clock is not None
        limit = min(timeout, self._budget_left())
        spent: float | None = None
        self._clock.start()
        wall_deadline = time.monotonic() + wall_backstop(limit)
        try:
            frames.send_message(self._sock, message)
            while True:
                answer = self._await(limit, wall_deadline)
                if not (isinstance(answer, dict) and answer.get("op") == "callback"):
                    break
                reply = (self.on_callback(answer) if self.on_callback is not None else
                         {"op": "callback-result", "ok": False, "error": "no callbacks"})
                frames.send_message(self._sock, reply)
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
            self.cpu_seconds += spent if spent is not None else self._clock.own()
        if not isinstance(answer, dict):
            self._kill()
            raise WorkerCrashed(f"{what}: the worker sent a malformed answer.")
        return answer

    def call(self, name: str, args: Sequence[Any], kwargs: dict[str, Any], *,
             timeout: float, figures: bool = False) -> tuple[Any, list[Any]]:
        """Call the student's ``name(*args, **kwargs)``; return (value, figures)."""
        what = f"{name}()"
        # Counted only when a time-out needs it: a recursive walk of every argument
        # cost the grader about 2% of its time on the hull checks.
        smallest = self.timed_out.get(name)
        if smallest is not None and payload_size([list(args), kwargs]) >= smallest[0]:
            raise NotRun(f"{what} was not run on this input, because `{name}` ran out of "
                         f"time on {smallest[1]}, an input at least as small.")
        count, earlier = self.strikes.get(name, (0, None))
        if earlier is not None and count >= MAX_STRIKES:
            # A function that crashed twice would cost a restart on every remaining
            # check, starving the other functions' checks.
            raise NotRun(f"{what} was not run: {earlier} (it did so {count} times, so it "
                         "was not called again)")
        try:
            answer = self.request({"op": "call", "name": name, "args": list(args),
                                   "kwargs": kwargs, "figures": figures},
                                  timeout=timeout, what=what)
        except CallTimeout:
            size = payload_size([list(args), kwargs])
            where = self.current_check or f"an input of size {size}"
            self.timed_out[name] = (min(size, self.timed_out.get(name, (size, ""))[0]), where)
            raise
        except WorkerCrashed as exc:
            self.strikes[name] = (count + 1, exc)
            raise
        if not answer.get("ok"):
            raise answer_error(name, answer)
        value = answer.get("value")
        if isinstance(value, values.Unsupported):
            raise UnsupportedValue(
                f"{name} returned a {value.type[:100]}, which the grader cannot read: return "
                "a number, a list or tuple of numbers, or a numpy array.")
        return value, list(answer.get("figures", []))

    def figures(self, *, timeout: float) -> list[Any]:
        answer = self.request({"op": "figures"}, timeout=timeout, what="drawing your figures")
        return list(answer.get("value", []))


def answer_error(name: str, answer: dict[str, Any]) -> Exception:
    """The error a failed answer stands for, every field cut to size (the proxy uses it
    for the functions a student returned, so both kinds of call meet the same caps)."""
    error = answer.get("error")
    if error == "missing":
        return MissingFunction(
            f"Your notebook does not define `{name}`. Define a function with exactly this "
            "name at the top level of a code cell, and run every cell before submitting.")
    if error == "not-callable":
        return MissingFunction(
            f"`{name}` in your notebook is a {str(answer.get('type'))[:100]}, not a function.")
    if error == "exception" and answer.get("type") == "NotAllowedError":
        # Raised by the worker's guard when code reached a forbidden library at run time.
        return ForbiddenUse(f"{name} used a library this assignment does not allow: "
                            f"{str(answer.get('message', ''))[:500]}")
    if error == "exception":
        exc_type = str(answer.get("type", ""))[:100]
        detail = str(answer.get("message", ""))[:2000]
        return StudentException(f"{name} raised {exc_type}: {detail}",
                                traceback=str(answer.get("traceback", ""))[:20_000],
                                function=name, exc_type=exc_type, detail=detail)
    if error == "unsupported":
        return UnsupportedValue(
            f"{name} returned a value the grader cannot read ({str(answer.get('message'))[:300]}).")
    return WorkerCrashed(f"{name}: the worker answered {str(error)[:100]!r}.")


def _policy_to_wire(policy: IsolationPolicy) -> dict[str, Any]:
    data = asdict(policy)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in data.items()}
