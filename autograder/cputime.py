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

__all__ = ["CpuClock", "process_cpu_seconds", "queued_seconds", "session_cpu_seconds"]

_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _stat_fields(pid: int) -> list[str] | None:
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:
            raw = handle.read()
    except OSError:  # gone, or not Linux
        return None
    # The command name (field 2) may hold spaces and parentheses: split after the last ')'.
    return raw.rsplit(b")", 1)[1].decode("ascii", "replace").split()


def process_cpu_seconds(pid: int) -> float:
    """User + system time of ``pid`` and its reaped children; 0.0 when it is gone."""
    fields = _stat_fields(pid)
    if fields is None:
        return 0.0
    # fields[0] is field 3 of proc(5): utime, stime, cutime, cstime are fields 14-17.
    return sum(int(fields[i]) for i in range(11, 15)) / _TICKS


def queued_seconds(pid: int) -> float:
    """Run-queue wait of ``pid``'s main thread (``/proc/<pid>/schedstat``, field 2); 0.0 if unknown."""
    try:
        with open(f"/proc/{pid}/schedstat", "rb") as handle:
            return int(handle.read().split()[1]) / 1e9
    except (OSError, IndexError, ValueError):
        return 0.0


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
            found[int(name)] = sum(int(fields[i]) for i in range(11, 15)) / _TICKS
    return found


@dataclass
class CpuClock:
    """CPU seconds a child's session spent since :meth:`start`.

    The child's own time is read at every :meth:`start` (one small file); the rest
    of its session is scanned only from :meth:`used`, and each other process is
    charged only for the time it spent since it was last charged, so a process
    left running by the notebook is charged to the call during which it runs.
    """

    pid: int
    _start: float = 0.0
    _queued_start: float = 0.0
    _others: float = 0.0
    _charged: dict[int, float] = field(default_factory=dict)

    def start(self) -> None:
        self._start = process_cpu_seconds(self.pid)
        self._queued_start = queued_seconds(self.pid)
        self._others = 0.0

    def queued(self) -> float:
        """Seconds the child was runnable but waiting for a CPU since :meth:`start`.

        A busy machine makes this grow; the wall-clock backstop adds it back, so
        only time the child itself spent (computing, sleeping, blocking) counts.
        """
        return max(0.0, queued_seconds(self.pid) - self._queued_start)

    def own(self) -> float:
        """The child's own CPU seconds since :meth:`start` (cheap)."""
        return max(0.0, process_cpu_seconds(self.pid) - self._start)

    def used(self) -> float:
        """CPU seconds of the child and its session since :meth:`start`."""
        for pid, seconds in session_cpu_seconds(self.pid, exclude=self.pid).items():
            before = self._charged.get(pid, 0.0)
            self._charged[pid] = seconds
            self._others += max(0.0, seconds - before)
        return self.own() + self._others
