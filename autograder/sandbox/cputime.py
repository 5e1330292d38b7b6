"""CPU time used by a sandboxed child and everything it started.

Time limits on student code are CPU limits: a submission gets the same verdict
on an idle laptop and on a grading server whose cores are all busy. A submission
may do its work in processes that live a millisecond, between two readings of
the clock, so the clock counts time that has already been *accounted* somewhere
rather than only what it sees running:

* as root, the slot's cgroup (``cpu.stat`` ``usage_usec`` on cgroup v2,
  ``cpuacct.usage`` on v1) counts every process that ever ran in it, exited ones
  included; the child joins the cgroup before any student code runs, and only root
  can move a process out;
* otherwise the clock adds up ``/proc/<pid>/stat`` (user + system time of a process
  and of the children it has reaped) of the child, of every process of its session
  (the child called ``setsid`` and seccomp forbids leaving the session; zombies
  still hold their time), and the reaped children's time of the warm parent, which
  is the child subreaper: a process whose parent exited is re-parented to it (or to
  the init of the child's PID namespace, a process of the session) and its time
  lands there once it is reaped. An exited process's time is thus always in one
  place: its zombie, or the process that reaped it.

Why by hand: ``psutil`` would do the same reading of ``/proc`` but is not a
dependency of the engine, and ``resource.getrusage`` only sees reaped children
of the calling process, not the grandchildren of a sibling.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from autograder.sandbox import cgroups
from autograder.sandbox.policy import IsolationPolicy

__all__ = ["CpuClock", "process_cpu_seconds", "session_cpu_seconds", "slot_clock"]

_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat_fields(pid: int) -> list[str] | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            raw = handle.read()
    except OSError:  # gone, or not Linux
        return None
    return _split_stat(raw)


def _split_stat(raw: bytes) -> list[str]:
    # The command name (field 2) may hold spaces and parentheses: split after the last ')'.
    return raw.rsplit(b")", 1)[1].decode("ascii", "replace").split()


def _cpu_of(fields: list[str] | None) -> float:
    if fields is None:
        return 0.0
    # fields[0] is field 3 of proc(5): utime, stime, cutime, cstime are fields 14-17.
    return sum(int(fields[i]) for i in range(11, 15)) / _TICKS


def _reaped_of(raw: bytes | None) -> float:
    """Time of the reaped children (cutime + cstime) in a raw ``stat``; 0.0 if unknown."""
    if raw is None:
        return 0.0
    fields = _split_stat(raw)
    return (int(fields[13]) + int(fields[14])) / _TICKS if len(fields) > 14 else 0.0


def _leads_namespace(pid: int) -> bool:
    """Whether ``pid`` is process 1 of a PID namespace of its own (``NSpid`` ends in 1)."""
    try:
        with open(f"/proc/{pid}/status", "rb") as handle:
            lines = handle.read().split(b"\n")
    except OSError:
        return False
    found = [line.split()[1:] for line in lines if line.startswith(b"NSpid:")]
    return bool(found) and len(found[0]) > 1 and found[0][-1] == b"1"


def _queued_of(raw: bytes | None) -> float:
    """Run-queue wait of a main thread from its ``/proc/<pid>/schedstat`` (field 2); 0.0 if unknown."""
    try:
        return int(raw.split()[1]) / 1e9 if raw is not None else 0.0
    except (IndexError, ValueError):
        return 0.0


def process_cpu_seconds(pid: int) -> float:
    """User + system time of ``pid`` and its reaped children; 0.0 when it is gone."""
    return _cpu_of(_stat_fields(pid))


class _ProcFile:
    """One ``/proc/<pid>/`` or cgroup file, opened once and read afresh with ``pread`` at 0.

    The clock reads the child's files around every call a check makes (about 90
    calls per hull submission): opening, reading and closing them each time was
    about a third of the grader's CPU per call (the slot cgroup's usage file: 11 us
    against 1 us kept open). An open ``/proc/<pid>`` file belongs to that process,
    so a pid the kernel reuses later is never read.
    """

    __slots__ = ("_path", "_fd")

    def __init__(self, path: str) -> None:
        self._path = path
        self._fd = -2  # not opened yet; -1: could not be opened

    def read(self) -> bytes | None:
        if self._fd == -2:
            try:
                self._fd = os.open(self._path, os.O_RDONLY | os.O_CLOEXEC)
            except OSError:  # gone, or not Linux
                self._fd = -1
        if self._fd < 0:
            return None
        try:
            return os.pread(self._fd, 4096, 0)
        except OSError:  # the process is gone
            return None

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
        self._fd = -1


def session_cpu_seconds(sid: int, *, exclude: int | None = None) -> dict[int, float]:
    """CPU seconds of every live process whose session id is ``sid`` (but ``exclude``)."""
    found: dict[int, float] = {}
    try:
        entries = os.listdir("/proc")
    except OSError:
        return found
    for name in entries:
        if not name.isdigit() or int(name) == exclude:
            continue
        fields = _stat_fields(int(name))
        # field 6 of proc(5) is the session id: fields[3].
        if fields is not None and len(fields) > 14 and fields[3] == str(sid):
            found[int(name)] = _cpu_of(fields)
    return found


#: readings of /proc a total may take when a process is reaped during one (then a
#: reaped process may have been counted twice, or not at all)
_TRIES = 3


@dataclass
class CpuClock:
    """CPU seconds a child and everything it started spent since :meth:`start`.

    ``usage`` is the slot cgroup's usage file (as root); without it the clock adds
    up ``/proc`` as the module says, with ``reaper`` the warm parent. :meth:`own` is
    the cheap reading for the end of every call: the child's files, kept open, and a
    scan of ``/proc`` only when the child, its PID namespace's init or the warm
    parent has a child of its own to count; :meth:`used` always scans. Totals never
    go down, so a process counted in one reading is not lost by the next.
    """

    pid: int
    reaper: int | None = None
    usage: cgroups.SlotCgroup | None = None
    _start: float = 0.0
    _queued_start: float = 0.0
    _stat: _ProcFile = field(init=False)
    _schedstat: _ProcFile = field(init=False)
    _files: dict[str, _ProcFile] = field(init=False, default_factory=dict)
    #: the total at the last reading (see :meth:`start`)
    _last: float | None = None
    #: the highest total read so far
    _high: float = 0.0
    _closed: bool = False
    #: the schedstat file :meth:`queued` reads, once known
    _init: _ProcFile | None = None
    #: the slot cgroup's usage file, kept open (with ``usage``)
    _usage_file: _ProcFile | None = None

    def __post_init__(self) -> None:
        self._stat = _ProcFile(f"/proc/{self.pid}/stat")
        self._schedstat = _ProcFile(f"/proc/{self.pid}/schedstat")
        if self.usage is not None and self.usage.usage is not None:
            self._usage_file = _ProcFile(str(self.usage.usage))
        if self._cgroup_total() is None:
            self.usage = None  # no usage file: /proc, as for an ordinary user
            self._close_usage()

    def close(self) -> None:
        """Close the child's files; the clock then keeps its last reading."""
        self._closed = True
        for handle in (self._stat, self._schedstat, *self._files.values()):
            handle.close()
        self._close_usage()

    def _close_usage(self) -> None:
        if self._usage_file is not None:
            self._usage_file.close()
            self._usage_file = None

    def _cgroup_total(self) -> float | None:
        """CPU seconds in the slot cgroup's usage file; None without one."""
        raw = None if self._usage_file is None else self._usage_file.read()
        return None if raw is None or self.usage is None else cgroups.parse_usage(
            raw, self.usage.version)

    def _file(self, path: str) -> _ProcFile:
        handle = self._files.get(path)
        if handle is None:
            handle = self._files[path] = _ProcFile(path)
            if self._closed:
                handle.close()
        return handle

    def _children(self, pid: int) -> list[int]:
        raw = self._file(f"/proc/{pid}/task/{pid}/children").read()
        return [int(n) for n in raw.split()] if raw else []

    def _total(self, *, scan: bool) -> float:
        if self._closed:
            total = None
        elif self.usage is not None:
            total = self._cgroup_total()
        else:
            total = self._proc_total(scan)
        if total is not None:
            self._high = max(self._high, total)
        self._last = self._high
        return self._high

    def _proc_total(self, scan: bool) -> float | None:
        raw = self._stat.read()
        if raw is None and self._last is None:
            return 0.0
        for _ in range(_TRIES):
            fixed, reaped = self._fixed()
            others = self._others(scan)
            if self._fixed()[1] == reaped:  # nothing was reaped meanwhile
                break
        return fixed + others

    def _fixed(self) -> tuple[float, float]:
        """(time of the child and the warm parent's reaped children, the reaped part)."""
        raw = self._stat.read()
        reaped = _reaped_of(raw)
        own = _cpu_of(None if raw is None else _split_stat(raw))
        if self.reaper is not None:
            reaper = _reaped_of(self._file(f"/proc/{self.reaper}/stat").read())
            own, reaped = own + reaper, reaped + reaper
        return own, reaped

    def _others(self, scan: bool) -> float:
        """Time of the other processes of the child's session."""
        children = self._children(self.pid)
        adopted = [] if self.reaper is None else [
            p for p in self._children(self.reaper) if p != self.pid]
        if not scan and not adopted and len(children) <= 1:
            if not children:
                return 0.0
            init = children[0]  # the child's PID namespace's init, or its one child
            if not self._children(init):
                return _cpu_of(_split_stat(self._file(f"/proc/{init}/stat").read() or b")"))
        return sum(session_cpu_seconds(self.pid, exclude=self.pid).values())

    def start(self) -> None:
        """Start counting from now: from the last reading, when there was one.

        The child waits for the next request between two calls, so the reading
        taken at the end of the last call is its time now (what it spends meanwhile,
        sending its answer and waiting again, is counted with the next call rather
        than not at all), and one read of ``/proc`` per call is saved.
        """
        self._start = self._last if self._last is not None else self._total(scan=True)
        self._queued_start = self._queued()

    def _queued(self) -> float:
        """Run-queue wait of the student's first process: the child, or the init of its
        PID namespace when the child is the relay that waits for it."""
        if self._init is None:
            children = self._children(self.pid)
            if len(children) != 1 or not _leads_namespace(children[0]):
                return _queued_of(self._schedstat.read())  # no relay, or not forked yet
            self._init = self._file(f"/proc/{children[0]}/schedstat")
        return _queued_of(self._init.read())

    def queued(self) -> float:
        """Seconds the child was runnable but waiting for a CPU since :meth:`start`.

        A busy machine makes this grow; the wall-clock backstop adds it back, so
        only time the child itself spent (computing, sleeping, blocking) counts.
        """
        return max(0.0, self._queued() - self._queued_start)

    def own(self) -> float:
        """CPU seconds of the child and what it started since :meth:`start` (cheap)."""
        return max(0.0, self._total(scan=False) - self._start)

    def used(self) -> float:
        """CPU seconds of the child and what it started since :meth:`start`."""
        return max(0.0, self._total(scan=True) - self._start)


def slot_clock(pid: int, policy: IsolationPolicy, slot: int, reaper: int | None) -> CpuClock:
    """The clock of the child ``pid`` of the warm parent ``reaper`` on worker slot ``slot``.

    As root with a slot cgroup, the cgroup's usage counts; otherwise ``/proc``.
    """
    group = (cgroups.slot_cgroup(slot, processes=policy.limits.processes, create=False)
             if policy.cgroup and os.geteuid() == 0 else None)
    return CpuClock(pid, reaper=reaper, usage=group)
