"""Trusted side of the boundary: start the warm parent, run one submission, make calls.

A :class:`WorkerSlot` owns one warm parent process (``python -m autograder.worker``).
A :class:`StudentSession` asks it for a fresh sandboxed child per submission,
waits for the notebook to run, and then sends calls with a time limit each.
The grader kills the child's whole process group on any timeout; it never
waits on student code without a deadline.
"""

from __future__ import annotations

import fcntl
import json
import os
import select
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from autograder import cgroups, protocol
from autograder.cputime import CpuClock
from autograder.errors import (
    AutograderError,
    CallTimeout,
    EngineError,
    ForbiddenUse,
    MissingFunction,
    NotRun,
    StudentError,
    StudentException,
    UnsupportedValue,
    WorkerCrashed,
)
from autograder.sandbox import IsolationPolicy

#: how long the warm parent may take to import numpy, scipy and matplotlib (our own
#: process, not student code: generous, so a loaded machine is slow but never wrong)
STARTUP_TIMEOUT = 600.0
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
    cpu_seconds: float = 0.0


#: where root graders claim slots (one lock file per sandbox user id): under /run, which
#: only root may write, so no other user can plant the folder or its files beforehand
ROOT_SLOT_LOCKS = Path("/run/autograder-slots")
MAX_SLOTS = 1000


def slot_lock_dir() -> Path:
    """The folder of slot locks for this grader's user.

    Root graders share one folder, because their slots pick sandbox user ids that
    must never be used by two graders at once. An ordinary user's children run as
    that user, so its graders share a folder of their own
    (``$TMPDIR/autograder-slots-<uid>``): root's folder never locks them out, and
    theirs never blocks root.
    """
    uid = os.geteuid()
    if uid == 0 and ROOT_SLOT_LOCKS.parent.is_dir():
        return ROOT_SLOT_LOCKS
    return Path(tempfile.gettempdir()) / f"autograder-slots-{uid}"


def _private_folder(path: Path) -> Path:
    """Create ``path`` (mode 700) or check that the existing one is ours and private.

    A folder another user made in a shared ``/tmp`` (or a link in its place) could
    hold links to other files or lock us out; it is refused with a clear message.
    """
    try:
        path.mkdir(mode=0o700)
    except FileExistsError:
        pass
    info = os.lstat(path)
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.geteuid() or info.st_mode & 0o077:
        raise AutograderError(
            f"the slot lock folder {path} is not a private folder of this user (owner uid "
            f"{info.st_uid}, mode {stat.S_IMODE(info.st_mode):o}); remove it, or set TMPDIR "
            "to a folder of your own, and start the grader again.")
    return path


def claim_slot(first: int = 0) -> tuple[int, int]:
    """Claim a slot number no other grader of this user holds; return (slot, lock fd).

    As root, the slot picks the sandbox's user id (``base_uid + slot``) and cgroup,
    and the grader kills every process of that user after each submission, so two
    graders running at the same time (two courses, two CI jobs) must never share
    one. An exclusive ``flock`` held for the slot's lifetime guarantees that, and the
    kernel releases it if the grader dies. Lock files are opened without following
    links.
    """
    folder = _private_folder(slot_lock_dir())
    for slot in range(first, first + MAX_SLOTS):
        fd = os.open(folder / f"{slot}.lock",
                     os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        return slot, fd
    raise AutograderError(f"all {MAX_SLOTS} worker slots in {folder} are taken; "
                          "is another grader stuck?")


#: the most characters of captured output the grader keeps from the worker
OUTPUT_CAP = 1 << 20
#: the most cell reports kept (each holds at most a 20,000-character traceback)
MAX_CELL_REPORTS = 200


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

    @property
    def warm_parent(self) -> int | None:
        """Pid of the running warm parent (the subreaper of every child), if any."""
        return self._proc.pid if self._proc is not None and self._proc.poll() is None else None

    def close(self) -> None:
        if self._control is not None:
            self._control.close()
            self._control = None
        if self._proc is not None:
            if self._proc.poll() is None:
                if os.geteuid() != 0:  # orphans it adopted would go to init with it
                    kill_descendants(self._proc.pid)
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


def kill_user(uid: int) -> bool:
    """Kill every process running as ``uid`` (the slot's own unprivileged user).

    A student's process can leave its process group with ``setsid``; it cannot
    leave its user. A helper forked from the grader becomes ``uid`` and calls
    ``kill(-1, SIGKILL)``: the kernel signals every process of that user in one pass
    under the task-list lock, and a process with a pending SIGKILL cannot fork, so
    a process that re-forks faster than a sweep through ``/proc`` is caught too.
    Repeated until no live process of ``uid`` is left (zombies count for ``kill``
    until their parent reaps them, so they are left out). Returns True when none is.
    """
    for _ in range(KILL_ROUNDS):
        pid = os.fork()
        if pid == 0:  # only system calls here: the grader may have threads
            code = 2
            try:
                os.setresuid(uid, uid, uid)
                os.kill(-1, signal.SIGKILL)
                code = 0
            except ProcessLookupError:
                code = 1  # nothing left to signal
            finally:
                os._exit(code)
        _, status = os.waitpid(pid, 0)
        if not os.WIFEXITED(status) or os.WEXITSTATUS(status) not in (0, 1):
            return False  # the helper could not become ``uid``
        if os.WEXITSTATUS(status) == 1 or not _live_processes(uid):
            return True
        time.sleep(0.002)  # let the killed exit
    return not _live_processes(uid)


def _live_processes(uid: int) -> list[int]:
    """Processes of ``uid`` that are not zombies."""
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:  # not the owner of /proc/<pid>: that is root for a process that changed ids
            with open(f"/proc/{name}/status", "rb") as handle:
                fields = dict(line.split(b":", 1) for line in handle.read().splitlines()
                              if b":" in line)
            real_uid, state = int(fields[b"Uid"].split()[0]), fields[b"State"].split()[0]
        except (OSError, KeyError, ValueError, IndexError):
            continue
        if real_uid == uid and state != b"Z":
            found.append(int(name))
    return found


def kill_descendants(root: int) -> bool:
    """Kill every descendant of ``root`` (the warm parent), round after round.

    For a grader that is not root (no user of the slot's own, no cgroup): the warm
    parent is a child subreaper, so a process whose parent died is re-parented to
    it rather than to init, and the whole tree stays below it. Each round kills
    what it finds; a killed process cannot fork again, so the rounds end. A listing
    of ``/proc`` is not atomic (a child may get a pid the listing already passed), so
    only several empty rounds in a row count as "none left". A backstop: the seccomp
    filter keeps every process in the child's process group, which is killed first.
    Returns True when none is left.
    """
    quiet = 0
    for _ in range(KILL_ROUNDS):
        found = _descendants(root)
        quiet = 0 if found else quiet + 1
        if quiet >= QUIET_ROUNDS:
            return True
        for pid in found:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        time.sleep(0.002)
    return not _descendants(root)


def _descendants(root: int) -> set[int]:
    parents: dict[int, int] = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        try:
            with open(f"/proc/{name}/stat", "rb") as handle:
                fields = handle.read().rsplit(b")", 1)[1].split()
        except OSError:
            continue
        if fields[0] != b"Z":  # zombies are dead already; their parent reaps them
            parents[int(name)] = int(fields[1])
    found: set[int] = set()
    frontier = {root}
    while frontier:
        frontier = {pid for pid, parent in parents.items() if parent in frontier} - found
        found |= frontier
    return found


#: rounds of killing before a sweep gives up (each round waits a few milliseconds)
KILL_ROUNDS = 500
#: empty listings in a row after which a sweep of descendants counts as done
QUIET_ROUNDS = 3


def sweep_slot(policy: IsolationPolicy, slot: int, warm_parent: int | None) -> None:
    """After a child is killed: make sure nothing it started is left on the slot.

    Root: the slot's cgroup (frozen, then killed), then the slot's user. An
    ordinary user: every descendant of the warm parent.
    """
    if os.geteuid() == 0:
        group = cgroups.slot_cgroup(slot, processes=policy.limits.processes, create=False)
        if policy.cgroup and group is not None:
            group.kill_all()
        if policy.drop_user:
            kill_user(policy.base_uid + slot)
    elif warm_parent is not None:
        kill_descendants(warm_parent)


@dataclass
class StudentSession:
    """One submission's sandboxed worker: run its cells, then answer calls.

    Time limits are CPU seconds of the child's session (see :mod:`autograder.cputime`),
    with a wall-clock backstop for code that sleeps or blocks, so a verdict never
    depends on how busy the machine is.
    """

    slot: WorkerSlot
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
    _sock: socket.socket | None = None
    _workdir: Path | None = None
    _clock: CpuClock | None = None
    _started_at: float | None = None
    report: RunReport | None = None

    # -- lifecycle -------------------------------------------------------
    def start(self) -> RunReport:
        """Run the notebook; a cell that hangs or kills the worker is skipped and the rest re-run."""
        begin = time.perf_counter()
        self._started_at = time.monotonic()
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
            crashed=self._pid is None, notes=tuple(notes), cpu_seconds=self.cpu_seconds)
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
                except (EOFError, OSError, protocol.ProtocolError) as exc:
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
                    elif op == "ready":
                        reports = [_cell_report(c) for c in message["cells"][:MAX_CELL_REPORTS]]
                        return "ready", None, (reports,
                                               str(message.get("stdout", ""))[:OUTPUT_CAP],
                                               [str(f)[:200] for f in message.get("functions", [])])
                except (KeyError, TypeError, ValueError):
                    self._kill()
                    return "crash", current, None
        finally:
            self.cpu_seconds += spent if spent is not None else self._clock.own()

    def _spawn(self) -> None:
        self._kill()
        self._workdir = Path(tempfile.mkdtemp(prefix="submission-"))
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
            "cells_json": json.dumps([[i, s] for i, s in self.cells if i not in self.skip]),
        }
        self._pid, self._sock = self.slot.spawn(request)
        self._clock = CpuClock(self._pid)

    def _await(self, cpu_limit: float, wall_deadline: float) -> Any:
        """The child's next message; TimeoutError once it used ``cpu_limit`` CPU seconds
        (since the clock's start) or the wall-clock backstop passed."""
        if self._sock is None or self._clock is None:
            raise EOFError("no worker")
        used = 0.0
        while True:
            # The backstop is pushed back by the time the child sat waiting for a CPU,
            # so a loaded machine does not make computing code look like waiting code.
            wall_left = wall_deadline + self._clock.queued() - time.monotonic()
            if used >= cpu_limit or wall_left <= 0:
                raise TimeoutError
            # CPU time cannot grow faster than wall time times the cores the child may use.
            wait = min(wall_left, max(MIN_POLL, (cpu_limit - used) / (os.cpu_count() or 1)))
            readable, _, _ = select.select([self._sock], [], [], wait)
            if readable:
                # A frame has started: the child may still stall inside it, so the
                # wall-clock backstop bounds the rest of the read.
                return protocol.recv_message(self._sock, timeout=max(wall_left, 1.0))
            used = self._clock.used()

    def _kill(self) -> None:
        if self._pid is not None:
            kill_group(self._pid)
            sweep_slot(self.policy, self.slot.slot, self.slot.warm_parent)
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
            protocol.send_message(self._sock, message)
            while True:
                answer = self._await(limit, wall_deadline)
                if not (isinstance(answer, dict) and answer.get("op") == "callback"):
                    break
                reply = (self.on_callback(answer) if self.on_callback is not None else
                         {"op": "callback-result", "ok": False, "error": "no callbacks"})
                protocol.send_message(self._sock, reply)
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
        size = payload_size([list(args), kwargs])
        if name in self.timed_out and size >= self.timed_out[name][0]:
            raise NotRun(f"{what} was not run on this input, because `{name}` ran out of "
                         f"time on {self.timed_out[name][1]}, an input at least as small.")
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
            where = self.current_check or f"an input of size {size}"
            self.timed_out[name] = (min(size, self.timed_out.get(name, (size, ""))[0]), where)
            raise
        except WorkerCrashed as exc:
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
    return WorkerCrashed(f"{name}: the worker answered {error!r}.")


def _policy_to_wire(policy: IsolationPolicy) -> dict[str, Any]:
    data = asdict(policy)
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in data.items()}
