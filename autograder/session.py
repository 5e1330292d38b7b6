"""Trusted side of the boundary: start the warm parent, run one submission, make calls.

A :class:`WorkerSlot` owns one warm parent process (``python -m autograder.worker``).
A :class:`StudentSession` asks it for a fresh sandboxed child per submission,
waits for the notebook to run, and then sends calls with a time limit each.
The grader kills the child's whole process group on any timeout; it never
waits on student code without a deadline.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

from autograder import protocol
from autograder.errors import (
    AutograderError,
    CallTimeout,
    MissingFunction,
    StudentError,
    StudentException,
    UnsupportedValue,
    WorkerCrashed,
)
from autograder.sandbox import IsolationPolicy

#: how long the warm parent may take to import numpy, scipy and matplotlib
STARTUP_TIMEOUT = 120.0
#: how many cells that hang or kill the worker are skipped before giving up on a notebook
MAX_RESTARTS = 2
#: how many times a submission's worker is restarted after a call hung or killed it
MAX_CALL_RESTARTS = 8
#: after this many hangs or crashes, a function is not called again for this submission
MAX_STRIKES = 2


@dataclass(frozen=True)
class CellReport:
    """How one code cell ended, as reported by the worker (plain data)."""

    index: int
    ok: bool
    seconds: float
    ename: str = ""
    evalue: str = ""
    traceback: str = ""


@dataclass(frozen=True)
class RunReport:
    """What running the notebook produced, before any check is run."""

    cells: tuple[CellReport, ...]
    stdout: str
    functions: tuple[str, ...]
    seconds: float
    timed_out_cells: tuple[int, ...] = ()
    crashed_cells: tuple[int, ...] = ()
    crashed: bool = False
    notes: tuple[str, ...] = ()


#: where slots are claimed (one lock file per sandbox user), shared by every grader here
SLOT_LOCKS = Path(tempfile.gettempdir()) / "autograder-slots"
MAX_SLOTS = 1000


def claim_slot(first: int = 0) -> tuple[int, int]:
    """Claim a slot number no other grader on this machine holds; return (slot, lock fd).

    The slot picks the sandbox's user id (``base_uid + slot``), and the grader kills
    every process of that user after each submission, so two graders running at the
    same time (two courses, two CI jobs) must never share one. An exclusive
    ``flock`` held for the slot's lifetime guarantees that, and the kernel releases
    it if the grader dies.
    """
    SLOT_LOCKS.mkdir(mode=0o700, exist_ok=True)
    for slot in range(first, first + MAX_SLOTS):
        fd = os.open(SLOT_LOCKS / f"{slot}.lock", os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        return slot, fd
    raise AutograderError(f"all {MAX_SLOTS} worker slots in {SLOT_LOCKS} are taken; "
                          "is another grader stuck?")


def _cell_report(data: Any) -> CellReport:
    """A :class:`CellReport` from the worker's plain data, every field checked."""
    return CellReport(index=int(data["index"]), ok=bool(data["ok"]),
                      seconds=float(data["seconds"]), ename=str(data.get("ename", ""))[:200],
                      evalue=str(data.get("evalue", ""))[:2000],
                      traceback=str(data.get("traceback", ""))[:20_000])


class WorkerSlot:
    """One warm parent process; forks a sandboxed child per submission."""

    def __init__(self, *, slot: int = 0, python: str = sys.executable) -> None:
        self.slot, self._lock = claim_slot(slot)
        self._python = python
        self._proc: subprocess.Popen[bytes] | None = None
        self._control: socket.socket | None = None
        self._home = Path(tempfile.mkdtemp(prefix="autograder-slot-"))

    def _start(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        env = {k: v for k, v in os.environ.items() if k in ("PATH", "LANG", "LC_ALL", "HOME")}
        env.update(MPLBACKEND="Agg", MPLCONFIGDIR=str(self._home / "mpl"),
                   OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self._proc = subprocess.Popen(
            [self._python, "-m", "autograder.worker", "--control-fd", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),), cwd=self._home, env=env,
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        theirs.close()
        self._control = ours
        try:
            hello = protocol.recv_message(ours, timeout=STARTUP_TIMEOUT)
        except (EOFError, OSError, protocol.ProtocolError) as exc:
            detail = self._stderr_tail()
            self.close()
            raise AutograderError(f"the grading worker did not start: {exc}. {detail}") from exc
        if not isinstance(hello, dict) or hello.get("op") != "hello":
            self.close()
            raise AutograderError("the grading worker sent an unexpected greeting")

    def _stderr_tail(self) -> str:
        if self._proc is None or self._proc.stderr is None:
            return ""
        try:
            self._proc.wait(timeout=1)
            return self._proc.stderr.read()[-2000:].decode("utf-8", "replace")
        except subprocess.TimeoutExpired:
            return ""

    def spawn(self, request: dict[str, Any]) -> tuple[int, socket.socket]:
        """Fork a child for ``request``; return its pid and the grader's socket end."""
        for attempt in (1, 2):
            if self._proc is None or self._proc.poll() is not None:
                self.close()
                self._start()
            ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                assert self._control is not None
                protocol.send_message(self._control, request)
                socket.send_fds(self._control, [b"F"], [theirs.fileno()])
                answer = protocol.recv_message(self._control, timeout=30)
                return int(answer["pid"]), ours
            except (OSError, EOFError, protocol.ProtocolError, KeyError, TypeError):
                ours.close()
                self.close()
                if attempt == 2:
                    raise
            finally:
                theirs.close()
        raise AssertionError("unreachable")

    def close(self) -> None:
        if self._control is not None:
            self._control.close()
            self._control = None
        if self._proc is not None:
            if self._proc.poll() is None:
                self._proc.kill()
            self._proc.wait()
            if self._proc.stderr is not None:
                self._proc.stderr.close()
            self._proc = None

    def shutdown(self) -> None:
        self.close()
        shutil.rmtree(self._home, ignore_errors=True)
        if self._lock >= 0:
            os.close(self._lock)
            self._lock = -1

    def __enter__(self) -> "WorkerSlot":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()


def kill_group(pid: int) -> None:
    """Kill the child's process group (it called setsid, so pgid == pid)."""
    for target in (lambda: os.killpg(pid, signal.SIGKILL), lambda: os.kill(pid, signal.SIGKILL)):
        try:
            target()
        except (ProcessLookupError, PermissionError):
            pass


def kill_user(uid: int) -> None:
    """Kill every process running as ``uid`` (the slot's own unprivileged user).

    A student's process can leave its process group with ``setsid``; it cannot
    leave its user, so this sweeps up whatever ``kill_group`` missed.
    """
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            status = (entry / "status").read_text()
        except OSError:
            continue
        for line in status.splitlines():
            if line.startswith("Uid:"):
                if int(line.split()[1]) == uid:
                    try:
                        os.kill(int(entry.name), signal.SIGKILL)
                    except OSError:
                        pass
                break


@dataclass
class StudentSession:
    """One submission's sandboxed worker: run its cells, then answer calls."""

    slot: WorkerSlot
    cells: Sequence[tuple[int, str]]
    data_files: Sequence[tuple[Path, str]]
    policy: IsolationPolicy
    notebook_timeout: float
    exclude: Sequence[Path] = ()
    restarts: int = 0
    skip: dict[int, str] = field(default_factory=dict)
    #: per function: how often a call hung or ended the worker, and the last such error
    strikes: dict[str, tuple[int, StudentError]] = field(default_factory=dict)
    _pid: int | None = None
    _sock: socket.socket | None = None
    _workdir: Path | None = None
    report: RunReport | None = None

    # -- lifecycle -------------------------------------------------------
    def start(self) -> RunReport:
        """Run the notebook; a cell that hangs or kills the worker is skipped and the rest re-run."""
        begin = time.perf_counter()
        notes: list[str] = []
        cells: list[CellReport] = []
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
        self.report = RunReport(
            cells=tuple(cells), stdout=stdout,
            functions=tuple(functions), seconds=time.perf_counter() - begin,
            timed_out_cells=tuple(sorted(i for i, s in self.skip.items() if s == "timeout")),
            crashed_cells=tuple(sorted(i for i, s in self.skip.items() if s == "crash")),
            crashed=self._pid is None, notes=tuple(notes))
        return self.report

    def _run_once(self, notes: list[str]) -> tuple[str, int | None, Any]:
        """Run the cells once: ("ready", None, data), or ("timeout"|"crash", cell, None)."""
        self._spawn()
        deadline = time.monotonic() + self.notebook_timeout
        current: int | None = None
        while True:
            try:
                message = self._recv(deadline)
            except TimeoutError:
                self._kill()
                return "timeout", current, None
            except (EOFError, OSError, protocol.ProtocolError):
                self._kill()
                return "crash", current, None
            if not isinstance(message, dict):
                continue
            try:  # the child is untrusted: a malformed message counts as a crash
                if message.get("op") == "started":
                    notes[:] = [str(n) for n in message.get("notes", [])]
                elif message.get("op") == "cell":
                    current = int(message["index"])
                elif message.get("op") == "ready":
                    return "ready", None, ([_cell_report(c) for c in message["cells"]],
                                           str(message.get("stdout", "")),
                                           [str(f) for f in message.get("functions", [])])
            except (KeyError, TypeError, ValueError):
                self._kill()
                return "crash", current, None

    def _spawn(self) -> None:
        self._kill()
        self._workdir = Path(tempfile.mkdtemp(prefix="submission-"))
        for source, relative in self.data_files:
            target = self._workdir / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(source, target)
        request = {
            "op": "spawn", "workdir": str(self._workdir), "slot": self.slot.slot,
            "policy": _policy_to_wire(self.policy),
            "exclude": [str(p) for p in self.exclude],
            "cells": [[i, s] for i, s in self.cells if i not in self.skip],
        }
        self._pid, self._sock = self.slot.spawn(request)

    def _recv(self, deadline: float) -> Any:
        if self._sock is None:
            raise EOFError("no worker")
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise TimeoutError
        return protocol.recv_message(self._sock, timeout=remaining)

    def _kill(self) -> None:
        if self._pid is not None:
            kill_group(self._pid)
            if self.policy.drop_user and os.geteuid() == 0:
                kill_user(self.policy.base_uid + self.slot.slot)
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None

    def close(self) -> None:
        if self._sock is not None:
            try:
                protocol.send_message(self._sock, {"op": "bye"})
            except OSError:
                pass
        self._kill()
        self._pid = None

    # -- calls -------------------------------------------------------------
    def request(self, message: dict[str, Any], *, timeout: float, what: str) -> dict[str, Any]:
        """Send ``message`` and return the answer, or raise a :class:`StudentError`."""
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
        assert self._sock is not None
        try:
            protocol.send_message(self._sock, message)
            answer = protocol.recv_message(self._sock, timeout=timeout)
        except TimeoutError:
            self._kill()
            raise CallTimeout(
                f"{what} did not return within {timeout:g} s; look for a loop that never "
                "ends or work that grows too fast with the input size.") from None
        except protocol.ProtocolError as exc:
            self._kill()
            raise UnsupportedValue(
                f"{what} returned a value the grader cannot read ({exc}); return a number, "
                "a list or tuple of numbers, or a numpy array of a sensible size.") from None
        except (EOFError, OSError) as exc:
            self._kill()
            raise WorkerCrashed(
                f"{what} ended the worker process (it exited, was killed by a memory or "
                f"CPU limit, or crashed): {type(exc).__name__}.") from None
        if not isinstance(answer, dict):
            self._kill()
            raise WorkerCrashed(f"{what}: the worker sent a malformed answer.")
        return answer

    def call(self, name: str, args: Sequence[Any], kwargs: dict[str, Any], *,
             timeout: float, figures: bool = False) -> tuple[Any, list[Any]]:
        """Call the student's ``name(*args, **kwargs)``; return (value, figures)."""
        what = f"{name}()"
        count, earlier = self.strikes.get(name, (0, None))
        if earlier is not None and count >= MAX_STRIKES:
            # A function that hung (or crashed) twice would cost a full time limit and a
            # restart on every remaining check, starving the other functions' checks.
            raise type(earlier)(f"{earlier} (it did so {count} times, so it was not "
                                "called again)")
        try:
            answer = self.request({"op": "call", "name": name, "args": list(args),
                                   "kwargs": kwargs, "figures": figures},
                                  timeout=timeout, what=what)
        except (CallTimeout, WorkerCrashed) as exc:
            self.strikes[name] = (count + 1, exc)
            raise
        if not answer.get("ok"):
            raise _answer_error(name, answer)
        value = answer.get("value")
        if isinstance(value, protocol.Unsupported):
            raise UnsupportedValue(
                f"{name} returned a {value.type}, which the grader cannot read: return "
                "a number, a list or tuple of numbers, or a numpy array.")
        return value, list(answer.get("figures", []))

    def figures(self, *, timeout: float) -> list[Any]:
        answer = self.request({"op": "figures"}, timeout=timeout, what="drawing your figures")
        return list(answer.get("value", []))


def _answer_error(name: str, answer: dict[str, Any]) -> Exception:
    error = answer.get("error")
    if error == "missing":
        return MissingFunction(
            f"Your notebook does not define `{name}`. Define a function with exactly this "
            "name at the top level of a code cell, and run every cell before submitting.")
    if error == "not-callable":
        return MissingFunction(
            f"`{name}` in your notebook is a {answer.get('type')}, not a function.")
    if error == "exception":
        return StudentException(
            f"{name} raised {answer.get('type')}: {answer.get('message', '')}",
            traceback=str(answer.get("traceback", "")))
    if error == "unsupported":
        return UnsupportedValue(
            f"{name} returned a value the grader cannot read ({answer.get('message')}).")
    return WorkerCrashed(f"{name}: the worker answered {error!r}.")


def _policy_to_wire(policy: IsolationPolicy) -> dict[str, Any]:
    data = asdict(policy)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in data.items()}
