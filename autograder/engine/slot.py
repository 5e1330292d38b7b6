"""Trusted side of the boundary: start the warm parent, run one submission, make calls.

A :class:`GradingSlot` owns one warm parent process (``python -m autograder.worker``).
A :class:`StudentProcess` asks it for a fresh sandboxed child per submission,
waits for the notebook to run, and then sends calls with a time limit each.
The grader kills the child's whole process group on any timeout; it never
waits on student code without a deadline.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import gc
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
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, NamedTuple, Sequence

import numpy as np

from autograder.boundary import frames, values
from autograder.errors import (
    AutograderError,
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
from autograder.sandbox import affinity, cgroups
from autograder.sandbox.confine import IsolationPolicy, probe_support
from autograder.sandbox.cputime import CpuClock
from autograder.sandbox.tempdirs import OwnedFolder

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


def matplotlib_folder() -> Path:
    """Matplotlib's folder for the warm parents of this user, kept from run to run.

    In the private folder of :func:`slot_lock_dir`: matplotlib builds its font list
    there once (about half a CPU second) instead of at every warm parent's start, and
    no other user can plant a file in it. The sandboxed children have one of their own.
    """
    folder = _private_folder(slot_lock_dir()) / "matplotlib"
    folder.mkdir(mode=0o700, exist_ok=True)
    return folder


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


class GradingSlot:
    """One warm parent process; forks a sandboxed child per submission."""

    def __init__(self, *, slot: int = 0, python: str = sys.executable,
                 scratch: Path | None = None) -> None:
        self.slot, self._lock = claim_slot(slot)
        try:
            #: the core the warm parent and its children run on (see autograder.sandbox.affinity)
            self.core = affinity.slot_core(self.slot)
        except BaseException:  # a bad AUTOGRADER_PIN_CORES: the slot is not kept
            os.close(self._lock)
            raise
        self._python = python
        self._proc: subprocess.Popen[bytes] | None = None
        self._control: socket.socket | None = None
        self._greeted = False  # the running warm parent said hello: it is ready to fork
        # Under ``scratch`` when the caller has a folder that is cleaned up for it (a Dask
        # worker's own directory, which Dask removes even after the worker was killed).
        # Locked while this slot lives: the next slot removes it if this grader is killed.
        self._folder = OwnedFolder(prefix="autograder-slot-", parent=scratch)
        self._home = self._folder.path
        #: every submission's working directory is made in here (see StudentProcess);
        #: traversable (711) for the slot's sandbox user, readable by nobody else
        self.work_root = self._home / "work"
        self.work_root.mkdir(mode=0o711)
        os.chmod(self.work_root, 0o711)  # mkdir's mode is masked by the umask
        os.chmod(self._home, 0o711)

    def start(self, *, wait: bool = True) -> None:
        """Start the warm parent unless it runs; with ``wait``, return once it is ready.

        ``wait=False`` returns at once, so its imports run while the caller works (the
        next :meth:`spawn`, or ``start()``, waits for its hello).
        """
        if self._proc is None or self._proc.poll() is not None:
            self.close()
            self._launch()
        if wait and not self._greeted:
            self._greet()

    def _launch(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        env = {k: v for k, v in os.environ.items() if k in ("PATH", "LANG", "LC_ALL", "HOME")}
        env.update(MPLBACKEND="Agg", MPLCONFIGDIR=str(matplotlib_folder()),
                   OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self._proc = subprocess.Popen(
            [self._python, "-m", "autograder.worker", "--control-fd", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),), cwd=self._home, env=env,
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        theirs.close()
        affinity.pin_process(self._proc.pid, self.core)  # before it starts any thread
        self._control = ours
        self._greeted = False

    def _greet(self) -> None:
        assert self._control is not None
        try:
            hello = frames.recv_message(self._control, timeout=STARTUP_TIMEOUT)
        except (EOFError, OSError, ProtocolError) as exc:
            detail = self._stderr_tail()
            self.close()
            raise AutograderError(f"the grading worker did not start: {exc}. {detail}") from exc
        if not isinstance(hello, dict) or hello.get("op") != "hello":
            self.close()
            raise AutograderError("the grading worker sent an unexpected greeting")
        self._greeted = True

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
            self.start()
            ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                assert self._control is not None
                frames.send_message(self._control, request)
                socket.send_fds(self._control, [b"F"], [theirs.fileno()])
                answer = frames.recv_message(self._control, timeout=30)
                return int(answer["pid"]), ours
            except (OSError, EOFError, ProtocolError, KeyError, TypeError):
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
        self._greeted = False
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
        self._folder.remove()
        if self._lock >= 0:
            os.close(self._lock)
            self._lock = -1

    def __enter__(self) -> "GradingSlot":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()


def start_early(*, slot: int = 0) -> GradingSlot:
    """A slot whose warm parent starts now, before the caller imports the rest of the engine.

    The warm parent imports numpy, scipy, matplotlib and IPython (about a second of
    CPU) and comes before the first result; started here, it imports beside the
    caller's own imports and check collection instead of after them (0.2 s sooner
    to the first result on 2 cores). The command line's ``grade``, ``check`` and
    ``validate`` call this first thing. The caller owns the slot: it hands it to
    :class:`~autograder.engine.grader.Grader` (``worker=``) and calls
    :meth:`GradingSlot.shutdown` in the end (safe after the grader closed it too).
    """
    worker = GradingSlot(slot=slot)
    try:
        worker.start(wait=False)
    except OSError:  # it is started again when needed, and what failed is reported there
        pass
    return worker


def child_pidfd(pid: int, parent: int | None) -> int | None:
    """A pidfd of the child ``pid`` that the warm parent ``parent`` just forked, or None.

    Taken at spawn; every later signal to the child goes through it (see
    :func:`kill_child`). The pidfd is trusted only once ``/proc`` shows its number as
    a child of ``parent`` *and* the pidfd's process is still unreaped after that
    reading, so the reading was about that very process. None when the child is
    gone already (the sweep ends whatever it started) or the kernel has no pidfds.
    """
    if parent is None or not cgroups.pidfds_supported():
        return None
    try:
        fd = cgroups.pidfd_open(pid)
    except OSError:
        return None
    if fd is None:
        return None
    info = _proc_stat(pid)
    if info is not None and info.ppid == parent and cgroups.pidfd_unreaped(fd):
        return fd
    os.close(fd)
    return None


def kill_child(pid: int, pidfd: int | None) -> None:
    """Kill the child's process group (it called setsid, so pgid == pid), then the child.

    Through the pidfd taken at spawn, never by number: the warm parent reaps the
    child the moment it exits (on SIGCHLD), and from then on the number may be
    handed to an unrelated process (pid_max can be as low as 32768), which a
    ``killpg(pid)`` or ``kill(pid)`` would hit. A pidfd names the child's own pid
    object, so the group signal (Linux 6.9+) reaches the child's group even after
    the child was reaped, and no other. On an older kernel the group is signalled by
    number only while the leader is unreaped (an unreaped process keeps its number
    from being handed out). No pidfd: the child was gone before it could be
    confirmed, so nothing is signalled here and the sweep ends what it left; by
    number only on a kernel without pidfds at all (before Linux 5.3).
    """
    if pidfd is None:
        if not cgroups.pidfds_supported():
            for kill in (os.killpg, os.kill):
                _quietly(kill, pid)
        return
    try:
        cgroups.pidfd_kill(pidfd, group=True)
    except PermissionError:
        pass
    except OSError as exc:  # EINVAL: no PIDFD_SIGNAL_PROCESS_GROUP before Linux 6.9
        if exc.errno == errno.EINVAL and cgroups.pidfd_unreaped(pidfd):
            _quietly(os.killpg, pid)
    try:  # the child itself: before its setsid it leads no group
        cgroups.pidfd_kill(pidfd)
    except PermissionError:
        pass


def _quietly(kill: Callable[[int, int], None], pid: int) -> None:
    try:
        kill(pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def kill_user(uid: int, *, confirm: bool = True) -> bool:
    """Kill every process running as ``uid`` (the slot's own unprivileged user).

    A student's process can leave its process group with ``setsid``; it cannot
    leave its user. ``kill(-1, SIGKILL)`` with ``uid``'s identity signals every
    process of that user in one pass under the task-list lock, and a process with
    a pending SIGKILL cannot fork, so a process that re-forks faster than a sweep
    through ``/proc`` is caught too. ``kill(-1)`` succeeds whenever any other
    process exists (the kernel counts those it may not signal), so what is left is
    read from ``/proc`` (:func:`_live_processes`, zombies left out), and the rounds
    repeat until nothing is. With ``confirm=False`` one ``kill(-1)`` is sent and
    ``/proc`` is not read: for a caller that saw the submission's first process in
    the slot's cgroup and the cgroup empty afterwards (every process the submission
    started was in it, and it is gone). Returns True when none is left.
    """
    cheap = _thread_switch_possible()
    for _ in range(KILL_ROUNDS):
        outcome = _signal_user_from_thread(uid) if cheap else None
        if outcome is None:
            cheap = False
            outcome = _signal_user_from_fork(uid)
        if outcome == "refused":
            return False  # ``uid``'s identity could not be taken
        if outcome == "none" or not confirm or not _live_processes(uid):
            return True
        time.sleep(0.002)  # let the killed exit
    return not _live_processes(uid)


def _signal_user_from_fork(uid: int) -> str:
    """``kill(-1, SIGKILL)`` from a forked helper that becomes ``uid``:
    "signalled", "none" (``ESRCH``) or "refused" (it could not become ``uid``)."""
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
        return "refused"
    return "none" if os.WEXITSTATUS(status) == 1 else "signalled"


#: setresuid(2) by machine, for :func:`_signal_user_from_thread` (147 in the generic table)
_SETRESUID = {"x86_64": 117, "aarch64": 147, "riscv64": 147, "loongarch64": 147}


def _thread_switch_possible() -> bool:
    """Whether the sweep may take the slot user's identity in a thread of the grader.

    For the moment the thread holds that identity, a process of the slot's user
    could try to ``ptrace`` it, which would expose the grader's memory (hidden
    checks, model solutions). Two walls must both stand, else the sweep forks: the
    kernel marks the grader non-dumpable when the thread's effective uid changes
    (only while ``fs.suid_dumpable`` is 0), and Landlock keeps every sandboxed
    process from tracing anything outside its own domain.
    """
    return (os.geteuid() == 0 and os.uname().machine in _SETRESUID
            and _read_proc("/proc/sys/fs/suid_dumpable", 16) == b"0\n"
            and probe_support().landlock_abi >= 1)


def _signal_user_from_thread(uid: int) -> str | None:
    """``kill(-1, SIGKILL)`` from a short-lived thread that alone takes ``uid``'s identity.

    Forking the grader costs tens of milliseconds (its page tables are large); a
    thread costs a fraction of one. The kernel keeps credentials per thread: the C
    library's ``setresuid`` changes every thread of the process, the raw system
    call only the calling one, so the grader's other threads stay root. The thread
    becomes real and effective ``uid`` with root as its saved uid (to come back),
    and checks in ``/proc`` that its real and effective uid are ``uid`` and that it
    has no effective capability before it signals: it then reaches exactly the
    processes the forked helper would. The garbage collector is paused meanwhile,
    so no finalizer of other code runs in the thread with that identity. Returns
    "signalled" or "none" (``ESRCH``), or None when the identity could not be taken
    as required (the caller then forks).
    """
    outcome: list[str | None] = [None]
    thread = threading.Thread(target=_kill_as, args=(uid, _SETRESUID[os.uname().machine], outcome),
                              name="autograder-sweep", daemon=True)
    thread.start()
    thread.join()
    return outcome[0]


def _kill_as(uid: int, number: int, outcome: list[str | None]) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    collecting = gc.isenabled()
    gc.disable()
    try:
        # real and effective uid ``uid``, saved uid 0: this thread only (see above)
        if libc.syscall(*(ctypes.c_long(n) for n in (number, uid, uid, 0))) != 0:
            return
        try:
            if _thread_identity() == (uid, uid, 0):
                try:
                    os.kill(-1, signal.SIGKILL)
                    outcome[0] = "signalled"
                except ProcessLookupError:
                    outcome[0] = "none"
        finally:
            libc.syscall(*(ctypes.c_long(n) for n in (number, 0, 0, 0)))  # root again
    finally:
        if collecting:
            gc.enable()


def _thread_identity() -> tuple[int, int, int] | None:
    """(real uid, effective uid, effective capabilities) of the calling thread, from /proc."""
    head = _read_proc(f"/proc/self/task/{threading.get_native_id()}/status", 8192)
    fields = _status_fields(head or b"", (b"Uid", b"CapEff"))
    try:
        real, effective = (int(v) for v in fields[b"Uid"].split()[:2])
        return real, effective, int(fields[b"CapEff"], 16)
    except (KeyError, ValueError):
        return None


def _live_processes(uid: int) -> list[int]:
    """Processes of ``uid`` that are not zombies.

    Reads the head of each ``/proc/<pid>/status`` (where ``State`` and ``Uid`` are)
    with plain system calls; the real uid is not in ``/proc/<pid>/stat``, and the
    owner of ``/proc/<pid>`` is root for a process that changed its ids.
    """
    found = []
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        fields = _status_fields(_read_proc(f"/proc/{name}/status", STATUS_HEAD) or b"",
                                (b"State", b"Uid"), name)
        try:
            real_uid, state = int(fields[b"Uid"].split()[0]), fields[b"State"].split()[0]
        except (KeyError, ValueError, IndexError):
            continue
        if real_uid == uid and state != b"Z":
            found.append(int(name))
    return found


def _status_fields(head: bytes, wanted: tuple[bytes, ...],
                   pid: str | None = None) -> dict[bytes, bytes]:
    """The ``wanted`` lines of a status file's ``head``; the whole file of ``pid`` is
    read when the head stops short of them (it never does on Linux today)."""
    fields = dict(line.split(b":", 1) for line in head.split(b"\n")[:-1] if b":" in line)
    if pid is not None and head and not all(key in fields for key in wanted):
        return _status_fields(_read_proc(f"/proc/{pid}/status", 1 << 16) or b"", wanted)
    return fields


def _read_proc(path: str, size: int) -> bytes | None:
    """Up to ``size`` bytes of a /proc file, by plain system calls; None if it is gone."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        return os.read(fd, size)
    except OSError:
        return None
    finally:
        os.close(fd)


class _ProcStat(NamedTuple):
    state: bytes
    ppid: int
    #: start time in clock ticks after boot: with the number, it names one process
    started: int


def _proc_stat(pid: int | str) -> _ProcStat | None:
    raw = _read_proc(f"/proc/{pid}/stat", 4096)
    if not raw:
        return None
    # The command name (field 2) may hold spaces and parentheses: split after the last ')'.
    fields = raw.rsplit(b")", 1)[-1].split()
    try:
        return _ProcStat(fields[0], int(fields[1]), int(fields[19]))
    except (IndexError, ValueError):
        return None


def kill_descendants(root: int) -> bool:
    """Kill every descendant of ``root`` (the warm parent), round after round.

    For a grader that is not root (no user of the slot's own, no cgroup): the warm
    parent is a child subreaper, so a process whose parent died is re-parented to
    it rather than to init, and the whole tree stays below it. Each round kills
    what it finds; a killed process cannot fork again, so the rounds end. A listing
    of ``/proc`` is not atomic (a child may get a pid the listing already passed), so
    only several empty rounds in a row count as "none left". A backstop: the seccomp
    filter keeps every process in the child's process group, which is killed first.
    Each process is signalled through a pidfd, and only if it is still the process
    the listing saw (same number and start time): the one listed may have been
    reaped since and its number handed to an unrelated process.
    Returns True when none is left.
    """
    quiet = 0
    for _ in range(KILL_ROUNDS):
        found = _descendants(root)
        quiet = 0 if found else quiet + 1
        if quiet >= QUIET_ROUNDS:
            return True
        for pid, started in found.items():
            _kill_listed(pid, started)
        time.sleep(0.002)
    return not _descendants(root)


def _kill_listed(pid: int, started: int) -> None:
    """SIGKILL ``pid`` if it is still the process that started at ``started``."""
    if not cgroups.pidfds_supported():
        _quietly(os.kill, pid)
        return
    try:
        fd = cgroups.pidfd_open(pid)
    except OSError:  # out of descriptors: the next round tries again
        return
    if fd is None:
        return
    try:
        info = _proc_stat(pid)  # read after the pidfd was opened: see child_pidfd
        if info is not None and info.started == started:
            cgroups.pidfd_kill(fd)
    except PermissionError:
        pass
    finally:
        os.close(fd)


def _descendants(root: int) -> dict[int, int]:
    """Live descendants of ``root``: pid -> start time (zombies are dead already)."""
    parents: dict[int, tuple[int, int]] = {}
    for name in os.listdir("/proc"):
        if not name.isdigit():
            continue
        info = _proc_stat(name)
        if info is not None and info.state != b"Z":  # zombies: their parent reaps them
            parents[int(name)] = (info.ppid, info.started)
    found: dict[int, int] = {}
    frontier = {root}
    while frontier:
        frontier = {pid for pid, (parent, _) in parents.items()
                    if parent in frontier and pid not in found}
        found.update((pid, parents[pid][1]) for pid in frontier)
    return found


#: rounds of killing before a sweep gives up (each round waits a few milliseconds)
KILL_ROUNDS = 500
#: empty listings in a row after which a sweep of descendants counts as done
QUIET_ROUNDS = 3
#: bytes read from the head of /proc/<pid>/status: ``State`` and ``Uid`` are in the first 300
STATUS_HEAD = 1024


def sweep_slot(policy: IsolationPolicy, slot: int, warm_parent: int | None,
               child: tuple[int, int] | None = None) -> None:
    """After a child is killed: make sure nothing it started is left on the slot.

    Root: the slot's cgroup (frozen, then killed), then the slot's user; with
    neither (both off by policy, or no usable cgroup and no user switch), every
    descendant of the warm parent. An ordinary user: every descendant of the warm
    parent.

    ``child`` (its pid and the pidfd from :func:`child_pidfd`, already sent ``SIGKILL``
    by :func:`kill_child`) spares the cgroup's freeze while it alone is left, and the
    reading of ``/proc`` for the slot's user in the common case: when the child is
    still in the slot's cgroup at the sweep and the cgroup is empty afterwards, every
    process the submission started was in it (the child joins it as root, before it
    takes the slot's user and runs any student code, and only root can move a process
    out), and is gone. The user's ``kill(-1)`` is still sent, for anything of that user
    outside the cgroup.
    """
    if os.geteuid() != 0:
        if warm_parent is not None:
            kill_descendants(warm_parent)
        return
    group = (cgroups.slot_cgroup(slot, processes=policy.limits.processes, create=False)
             if policy.cgroup else None)
    contained = False
    if group is not None:
        contained = child is not None and _in_cgroup(group, *child)
        # The child was killed before the sweep: while it alone is listed, the sweep
        # waits for it to exit rather than freezing the slot for a kill round.
        known = {child[0]: os.dup(child[1])} if child is not None and contained else {}
        contained = group.kill_all(killed=known) and contained
    if policy.drop_user:
        kill_user(policy.base_uid + slot, confirm=not contained)
    elif group is None and warm_parent is not None:
        kill_descendants(warm_parent)


def _in_cgroup(group: cgroups.SlotCgroup, pid: int, pidfd: int) -> bool:
    """Whether the process of ``pidfd`` (number ``pid``) is in ``group`` now.

    The listing is read first: if the pidfd's process is still unreaped afterwards,
    the number in the listing was that process's.
    """
    return pid in group.pids() and cgroups.pidfd_unreaped(pidfd)


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
            if cell is None or len(self.skip) >= MAX_RESTARTS + 1:
                self._kill()
                self._pid = None
                if cell is not None:
                    self.skip[cell] = status
                break
            self.skip[cell] = status
        self.report = NotebookRun(
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
            "cells_json": json.dumps([[i, s] for i, s in self.cells if i not in self.skip]),
        }
        if os.listdir(self.slot.work_root) == [self._workdir.name]:
            # The warm parent's one ruleset may then serve this child: it lets the child
            # change files anywhere in the work root, which holds nothing but its own
            # folder (a leftover that could not be removed makes the child build its own).
            request["workroot"] = str(self.slot.work_root)
        self._pid, self._sock = self.slot.spawn(request)
        self._pidfd = child_pidfd(self._pid, self.slot.warm_parent)
        self._clock = CpuClock(self._pid)

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
            raise _answer_error(name, answer)
        value = answer.get("value")
        if isinstance(value, values.Unsupported):
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
