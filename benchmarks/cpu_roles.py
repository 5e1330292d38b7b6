"""CPU seconds per process role of a run, sampled from ``/proc`` (Linux only).

Wall-clock rates are noisy on a shared machine; CPU seconds per role are not.
:class:`RoleSampler` watches this process and all its descendants every
``interval`` seconds and, at :meth:`RoleSampler.stop`, sums each process's own
CPU time (user + system, the last value seen) by role:

* ``client``: this process (for ``--dask local:N`` also the scheduler and the
  nannies, which run in it), split by thread name;
* ``slot process``: the local pool's processes, or the Dask worker processes;
* ``warm parent``: each slot's ``python -m autograder.worker``;
* ``student``: the sandboxed children the warm parents fork, counted from the
  warm parents' reaped-children time (a child lives a fraction of a second);
* ``other``: anything else (the resource tracker, sandbox probes).

``getrusage`` (self + reaped children) is printed beside them: it is exact for
the processes that were waited for all the way up (the local pool's processes
exit without closing their grader, so there it leaves out the warm parents and
the students).
"""

from __future__ import annotations

import os
import resource
import threading
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

TICK = os.sysconf("SC_CLK_TCK")


@dataclass
class _Seen:
    role: str
    own: float = 0.0
    reaped: float = 0.0


def _stat(pid: int, tid: int | None = None) -> tuple[int, float, float] | None:
    """(ppid, own CPU s, reaped children CPU s) of ``pid`` (or its thread ``tid``)."""
    path = f"/proc/{pid}/task/{tid}/stat" if tid is not None else f"/proc/{pid}/stat"
    try:
        text = Path(path).read_text()
    except OSError:
        return None
    fields = text[text.rindex(")") + 2:].split()
    # fields[0] is field 3 (state); utime, stime, cutime, cstime are fields 14..17
    utime, stime, cutime, cstime = (int(v) for v in fields[11:15])
    return int(fields[1]), (utime + stime) / TICK, (cutime + cstime) / TICK


def _children(pid: int) -> list[int]:
    """The live children of ``pid`` (from each thread's ``children`` list)."""
    found: list[int] = []
    try:
        for tid in os.listdir(f"/proc/{pid}/task"):
            try:
                found.extend(int(c) for c in Path(f"/proc/{pid}/task/{tid}/children").read_text().split())
            except OSError:
                pass
    except OSError:
        pass
    return found


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _role(cmdline: str, parent_role: str) -> str:
    if "autograder.worker" in cmdline:
        return "student" if parent_role in ("warm parent", "student") else "warm parent"
    if "resource_tracker" in cmdline:
        return "other"
    if "spawn_main" in cmdline:
        return "slot process"
    return "other"


@dataclass
class RoleSampler:
    """Samples the CPU time of this process tree by role until :meth:`stop`."""

    interval: float = 0.2
    _seen: dict[int, _Seen] = field(default_factory=dict)
    #: how many processes of each role were seen (filled by :meth:`stop`)
    processes: dict[str, int] = field(default_factory=dict)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None
    _start_usage: float = 0.0
    _sampler_cpu: float = 0.0

    def start(self) -> "RoleSampler":
        self._start_usage = _rusage_total()
        self._base = {tid: cpu for tid, cpu in self._thread_times().items()}
        own = _stat(os.getpid())
        self._client_base = own[1] if own else 0.0
        self._thread = threading.Thread(target=self._loop, name="cpu-role-sampler", daemon=True)
        self._thread.start()
        return self

    def _loop(self) -> None:
        while not self._stop.wait(self.interval):
            self.sample()
        self._sampler_cpu = time.thread_time()

    def sample(self) -> None:
        stack = [(pid, "client") for pid in _children(os.getpid())]
        while stack:
            pid, parent_role = stack.pop()
            stat = _stat(pid)
            if stat is None:
                continue
            seen = self._seen.get(pid)
            if seen is None:
                seen = self._seen[pid] = _Seen(_role(_cmdline(pid), parent_role))
            elif seen.role == "other":  # first seen between fork and exec: the parent's command
                seen.role = _role(_cmdline(pid), parent_role)
            seen.own, seen.reaped = max(seen.own, stat[1]), max(seen.reaped, stat[2])
            stack.extend((child, seen.role) for child in _children(pid))

    def _thread_times(self) -> dict[int, float]:
        times = {}
        for tid in os.listdir(f"/proc/{os.getpid()}/task"):
            stat = _stat(os.getpid(), int(tid))
            if stat is not None:
                times[int(tid)] = stat[1]
        return times

    def stop(self) -> dict[str, float]:
        """CPU seconds by role since :meth:`start` (descendants must have exited and been reaped)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.sample()
        roles: dict[str, float] = defaultdict(float)
        own = _stat(os.getpid())
        roles["client"] = (own[1] if own else 0.0) - self._client_base
        counts: dict[str, int] = defaultdict(int)
        for seen in self._seen.values():
            if seen.role != "student":  # counted through the warm parents' reaped time
                roles[seen.role] += seen.own
            if seen.role == "warm parent":
                roles["student"] += seen.reaped
            counts[seen.role] += 1
        self.processes = dict(counts)
        roles["total (getrusage)"] = _rusage_total() - self._start_usage
        roles["sampler thread"] = self._sampler_cpu
        return dict(roles)

    def client_threads(self) -> dict[str, float]:
        """CPU seconds of this process's live threads since :meth:`start`, by thread name."""
        names = {t.native_id: t.name for t in threading.enumerate()}
        by_name: dict[str, float] = defaultdict(float)
        for tid, cpu in self._thread_times().items():
            name = names.get(tid, "(non-Python or ended)")
            by_name[name.split("-")[0] if name.startswith("Dask") else name] += cpu - self._base.get(tid, 0.0)
        return dict(by_name)


def _rusage_total() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime
