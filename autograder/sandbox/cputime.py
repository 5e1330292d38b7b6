"""CPU time used by a sandboxed child and the processes of its session.

Time limits on student code are CPU limits: a submission gets the same verdict
on an idle laptop and on a grading server whose cores are all busy. The clock
reads ``/proc/<pid>/stat`` (user + system time of the process and of the
children it has reaped) and, only when a wait lasts long enough to matter, the
other processes of the child's session (the child called ``setsid``, so its
pid is the session id of everything it starts, unless a process starts a
session of its own, which the wall-clock backstop and the slot's user sweep
still catch).

Why by hand: ``psutil`` would do the same reading of ``/proc`` but is not a
dependency of the engine, and ``resource.getrusage`` only sees reaped children
of the calling process, not the grandchildren of a sibling.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

__all__ = ["CpuClock", "process_cpu_seconds", "session_cpu_seconds"]

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
    """One ``/proc/<pid>/`` file, opened once and read afresh with ``pread`` at offset 0.

    The clock reads the child's files around every call a check makes (about 90
    calls per hull submission): opening, reading and closing them each time was
    about a third of the grader's CPU per call. An open ``/proc/<pid>`` file
    belongs to that process, so a pid the kernel reuses later is never read.
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


@dataclass
class CpuClock:
    """CPU seconds a child's session spent since :meth:`start`.

    The child's own time is read at every :meth:`start` (one small file, kept
    open until :meth:`close`); the rest of its session is scanned only from
    :meth:`used`, and each other process is charged only for the time it spent
    since it was last charged, so a process left running by the notebook is
    charged to the call during which it runs.
    """

    pid: int
    _start: float = 0.0
    _queued_start: float = 0.0
    _others: float = 0.0
    _charged: dict[int, float] = field(default_factory=dict)
    _stat: _ProcFile = field(init=False)
    _schedstat: _ProcFile = field(init=False)
    #: the child's own total at the last reading (see :meth:`start`)
    _last: float | None = None

    def __post_init__(self) -> None:
        self._stat = _ProcFile(f"/proc/{self.pid}/stat")
        self._schedstat = _ProcFile(f"/proc/{self.pid}/schedstat")

    def close(self) -> None:
        """Close the child's files (the clock reads 0.0 of a process after this)."""
        self._stat.close()
        self._schedstat.close()

    def _own_total(self) -> float:
        raw = self._stat.read()
        self._last = _cpu_of(None if raw is None else _split_stat(raw))
        return self._last

    def start(self) -> None:
        """Start counting from now: from the last reading, when there was one.

        The child waits for the next request between two calls, so the reading
        taken at the end of the last call is its time now (what it spends meanwhile,
        sending its answer and waiting again, is counted with the next call rather
        than not at all), and one read of ``/proc`` per call is saved.
        """
        self._start = self._last if self._last is not None else self._own_total()
        self._queued_start = _queued_of(self._schedstat.read())
        self._others = 0.0

    def queued(self) -> float:
        """Seconds the child was runnable but waiting for a CPU since :meth:`start`.

        A busy machine makes this grow; the wall-clock backstop adds it back, so
        only time the child itself spent (computing, sleeping, blocking) counts.
        """
        return max(0.0, _queued_of(self._schedstat.read()) - self._queued_start)

    def own(self) -> float:
        """The child's own CPU seconds since :meth:`start` (cheap)."""
        return max(0.0, self._own_total() - self._start)

    def used(self) -> float:
        """CPU seconds of the child and its session since :meth:`start`."""
        for pid, seconds in session_cpu_seconds(self.pid, exclude=self.pid).items():
            before = self._charged.get(pid, 0.0)
            self._charged[pid] = seconds
            self._others += max(0.0, seconds - before)
        return self.own() + self._others
