"""Ending every process a sandboxed child started, and nothing else.

After each submission the grader kills the child (through the pidfd taken at
spawn, never by a number the kernel may have handed on), then sweeps the slot:
its cgroup, every process of its own user, or, for a grader that is not root,
every descendant of the warm parent. Each way has a fallback for kernels and
machines without the cheaper one; see :func:`sweep_slot`.
"""

from __future__ import annotations

import ctypes
import errno
import gc
import os
import signal
import threading
import time
from typing import Callable, NamedTuple

from autograder.sandbox import cgroups
from autograder.sandbox.pidfd import pidfd_kill, pidfd_open, pidfd_unreaped, pidfds_supported
from autograder.sandbox.policy import IsolationPolicy
from autograder.sandbox.support import probe_support

#: rounds of killing before a sweep gives up (each round waits a few milliseconds)
KILL_ROUNDS = 500
#: empty listings in a row after which a sweep of descendants counts as done
QUIET_ROUNDS = 3
#: bytes read from the head of /proc/<pid>/status: ``State`` and ``Uid`` are in the first 300
STATUS_HEAD = 1024


def child_pidfd(pid: int, parent: int | None) -> int | None:
    """A pidfd of the child ``pid`` that the warm parent ``parent`` just forked, or None.

    Taken at spawn; every later signal to the child goes through it (see
    :func:`kill_child`). The pidfd is trusted only once ``/proc`` shows its number as
    a child of ``parent`` *and* the pidfd's process is still unreaped after that
    reading, so the reading was about that very process. None when the child is
    gone already (the sweep ends whatever it started) or the kernel has no pidfds.
    """
    if parent is None or not pidfds_supported():
        return None
    try:
        fd = pidfd_open(pid)
    except OSError:
        return None
    if fd is None:
        return None
    info = _proc_stat(pid)
    if info is not None and info.ppid == parent and pidfd_unreaped(fd):
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
        if not pidfds_supported():
            for kill in (os.killpg, os.kill):
                _quietly(kill, pid)
        return
    try:
        pidfd_kill(pidfd, group=True)
    except PermissionError:
        pass
    except OSError as exc:  # EINVAL: no PIDFD_SIGNAL_PROCESS_GROUP before Linux 6.9
        if exc.errno == errno.EINVAL and pidfd_unreaped(pidfd):
            _quietly(os.killpg, pid)
    try:  # the child itself: before its setsid it leads no group
        pidfd_kill(pidfd)
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
    of ``/proc`` is not atomic (a child may get a pid the listing already passed, and
    a process that forks and exits at once is gone before its entry is read while its
    child was born after the listing), so a round is empty only when the listing finds
    nothing and ``root``'s own list of children, which the kernel keeps whole (an
    orphan moves to it as its parent exits), holds no live process and did not change
    while it was read; and only several empty rounds in a row count as "none left".
    A backstop: the seccomp
    filter keeps every process in the child's process group, which is killed first.
    Each process is signalled through a pidfd, and only if it is still the process
    the listing saw (same number and start time): the one listed may have been
    reaped since and its number handed to an unrelated process.
    Returns True when none is left.
    """
    quiet = 0
    for _ in range(KILL_ROUNDS):
        found = _descendants(root)
        children, changed = _live_children(root)
        found.update(children)
        quiet = 0 if found or changed else quiet + 1
        if quiet >= QUIET_ROUNDS:
            return True
        for pid, started in found.items():
            _kill_listed(pid, started)
        time.sleep(0.002)
    children, changed = _live_children(root)
    return not (_descendants(root) or children or changed)


def _child_list(root: int) -> set[int] | None:
    """The children of every thread of ``root``, as the kernel lists them; None once it is gone."""
    try:
        threads = os.listdir(f"/proc/{root}/task")
    except OSError:
        return None
    found: set[int] = set()
    for thread in threads:
        raw = _read_proc(f"/proc/{root}/task/{thread}/children", 1 << 20)
        found.update(int(n) for n in (raw or b"").split())
    return found


def _live_children(root: int) -> tuple[dict[int, int], bool]:
    """``root``'s live children (pid -> start time), and whether its list grew meanwhile.

    A child that exits just after the list was read may have forked first; its
    child then moved to ``root``'s list before it became a zombie, so the list read
    again afterwards shows the newcomer.
    """
    before = _child_list(root)
    if before is None:
        return {}, False
    live: dict[int, int] = {}
    for pid in before:
        info = _proc_stat(pid)
        if info is not None and info.state != b"Z":
            live[pid] = info.started
    after = _child_list(root)
    return live, bool((after or set()) - before)


def _kill_listed(pid: int, started: int) -> None:
    """SIGKILL ``pid`` if it is still the process that started at ``started``."""
    if not pidfds_supported():
        _quietly(os.kill, pid)
        return
    try:
        fd = pidfd_open(pid)
    except OSError:  # out of descriptors: the next round tries again
        return
    if fd is None:
        return
    try:
        info = _proc_stat(pid)  # read after the pidfd was opened: see child_pidfd
        if info is not None and info.started == started:
            pidfd_kill(fd)
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
    return pid in group.pids() and pidfd_unreaped(pidfd)
