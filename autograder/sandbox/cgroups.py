"""A control group per worker slot: equal CPU share, a process cap, and a sure kill.

Every process a submission starts stays in its slot's cgroup, whatever it does
(``setsid``, double fork, a new user id), so the grader can

* give each slot the same CPU weight: 48 busy processes of one submission share one
  slot's weight and cannot starve the honest submission on the other slot;
* cap the slot's processes (``pids.max``), a second bound besides ``RLIMIT_NPROC``;
* count the CPU time of everything that ran in it, processes that lived a
  millisecond included (``cpu.stat`` or ``cpuacct.usage``, see :mod:`autograder.sandbox.cputime`);
* kill everything in it, including processes that re-fork faster than a sweep
  through ``/proc``: ``cgroup.kill`` (cgroup v2), or freeze, kill, thaw (v1 freezer).

Where it applies: root, with the cgroup v2 ``cpu`` and ``pids`` controllers on the
unified hierarchy, or else with the v1 ``cpu`` (and, if mounted, ``pids``, ``cpuacct``
and ``freezer``) hierarchies. An ordinary user gets none (a delegated v2 subtree would
need the grader itself moved into a leaf first), and the grader says so once.

Why by hand: the cgroup file system *is* the interface (a few ``mkdir`` and
one-line writes), and the Python libraries for it (``cgroupspy``, ``libcgroup``
bindings) are unmaintained and v1-only.
"""

from __future__ import annotations

import errno
import functools
import os
import select
import time
from dataclasses import dataclass
from pathlib import Path

from autograder.sandbox.pidfd import signal_listed, still_killed

__all__ = ["SlotCgroup", "cgroup_support", "forget_created", "slot_cgroup"]

CGROUP_ROOT = Path("/sys/fs/cgroup")
#: name of the grader's folder in each hierarchy
GROUP = "autograder"
#: cpu.shares (v1) and cpu.weight (v2) of every slot: equal by construction
V1_SHARES = 1024
V2_WEIGHT = 100
#: how long a v1 freeze may take before the kill proceeds anyway
FREEZE_WAIT = 2.0
#: rounds of "kill what is listed" before giving up (each round waits a little)
KILL_ROUNDS = 200
#: the first wait after a round, doubled each round up to ROUND_PAUSE (seconds)
FIRST_PAUSE = 0.0005
ROUND_PAUSE = 0.005


@dataclass(frozen=True)
class SlotCgroup:
    """The directories of one slot's cgroup (one per v1 hierarchy, or one v2 group).

    Attributes
    ----------
    version : int
        1 or 2.
    dirs : tuple of Path
        The slot's directory in each hierarchy; the first one lists the processes.
    freezer : Path or None
        The v1 freezer directory, when that hierarchy is mounted.
    usage : Path or None
        The file counting the CPU time of every process that ever ran in the slot,
        exited ones included: ``cpu.stat`` (v2, ``usage_usec``) or ``cpuacct.usage``
        (v1, nanoseconds; its hierarchy's directory is one of ``dirs``); None when
        v1 has no ``cpuacct`` hierarchy.
    """

    version: int
    dirs: tuple[Path, ...]
    freezer: Path | None = None
    usage: Path | None = None

    def join(self) -> None:
        """Move the calling process (and so everything it will start) into the slot."""
        for directory in self.dirs + ((self.freezer,) if self.freezer else ()):
            (directory / "cgroup.procs").write_text("0")

    def pids(self) -> set[int]:
        """The processes now in the slot (an empty set once it is gone)."""
        try:
            text = (self.dirs[0] / "cgroup.procs").read_text()
        except OSError:
            return set()
        return {int(line) for line in text.split()}

    def kill_all(self, *, killed: dict[int, int] | None = None) -> bool:
        """Kill every process of the slot; True when none is left.

        ``killed`` names processes the caller has already sent ``SIGKILL`` (pid ->
        a pidfd of each, closed by this call): while only they are listed, the sweep
        just waits for them to exit, with no kill round (on cgroup v1, no freeze).

        A round kills what is listed: ``cgroup.kill`` (v2), or else each listed
        process while the slot is frozen (frozen processes cannot fork, so one such
        round kills them all; without a freezer, rounds repeat until the list stays
        empty, and ``pids.max`` bounds how many a round can meet). Between rounds
        the sweep only waits while every listed process is one it already killed
        (it is exiting and cannot fork), so a slot that is empty, or empty a moment
        later, costs a few small reads and no freeze.
        """
        killed = dict(killed or {})  # pid -> pidfd of a process killed by now
        exited: set[int] = set()  # killed processes whose pidfd said they exited
        try:
            for attempt in range(KILL_ROUNDS):
                listed = self.pids()
                if not listed:
                    return True
                if not all(still_killed(killed, pid) for pid in listed):
                    self._kill_round(killed)
                _wait_for_exit(killed, listed, exited, _pause(attempt))
            return not self.pids()
        finally:
            for fd in killed.values():
                os.close(fd)

    def _kill_round(self, killed: dict[int, int]) -> None:
        if self.version == 2:
            try:
                (self.dirs[0] / "cgroup.kill").write_text("1")
                return  # the kernel kills every member, and a fork racing with it
            except OSError:
                pass  # before Linux 5.14: one process at a time
        frozen = self._freeze()
        try:
            signal_listed(self.pids, killed)
        finally:
            if frozen:
                self._thaw()

    def _freeze(self) -> bool:
        if self.freezer is None:
            return False
        state = self.freezer / "freezer.state"
        try:
            state.write_text("FROZEN")
        except OSError:
            return False
        end = time.monotonic() + FREEZE_WAIT
        while state.read_text().strip() != "FROZEN" and time.monotonic() < end:
            time.sleep(0.001)
        return True

    def _thaw(self) -> None:
        # SIGKILL is delivered only to running tasks: thaw so that the killed exit.
        (self.freezer / "freezer.state").write_text("THAWED")  # type: ignore[operator]


def parse_usage(raw: bytes, version: int) -> float | None:
    """CPU seconds from the text of ``cpu.stat`` (v2) or ``cpuacct.usage`` (v1)."""
    try:
        if version == 1:
            return int(raw.split()[0]) / 1e9
        for line in raw.split(b"\n"):
            if line.startswith(b"usage_usec "):
                return int(line.split()[1]) / 1e6
    except (IndexError, ValueError):
        pass
    return None


def _wait_for_exit(killed: dict[int, int], listed: set[int], exited: set[int],
                   pause: float) -> None:
    """Wait until a listed process exits, or ``pause`` seconds.

    When every listed process is a killed one with a pidfd, the wait ends the moment
    one of them exits (a pidfd turns readable then) instead of after a fixed sleep:
    a killed child takes a few milliseconds to tear its memory down.
    """
    waiting = {killed[pid]: pid for pid in listed if pid in killed and pid not in exited}
    if not waiting or len(waiting) + len(exited & listed) < len(listed):
        time.sleep(pause)
        return
    poller = select.poll()  # not select(): a pidfd may be numbered above FD_SETSIZE
    for fd in waiting:
        poller.register(fd, select.POLLIN)
    exited.update(waiting[fd] for fd, _ in poller.poll(ROUND_PAUSE * 1000))


def _pause(attempt: int) -> float:
    """Seconds to wait after round ``attempt``: short at first (most processes exit in
    well under a millisecond), then :data:`ROUND_PAUSE`."""
    return min(ROUND_PAUSE, FIRST_PAUSE * 2 ** attempt)


def slot_cgroup(slot: int, *, processes: int, create: bool = True) -> SlotCgroup | None:
    """The slot's cgroup, created (as root) if needed; None where cgroups cannot be used.

    Parameters
    ----------
    slot : int
        The worker slot (unique on the machine while its lock is held).
    processes : int
        ``pids.max`` of the slot.
    create : bool
        Create the directories and write the settings (False: only find them).

    Returns
    -------
    SlotCgroup or None
    """
    layout = _layout()
    if layout is None:
        return None
    version, roots, freezer_root, usage_root = layout
    name = f"slot-{slot}"
    dirs = tuple(root / GROUP / name for root in roots)
    freezer = freezer_root / GROUP / name if freezer_root is not None else None
    usage = (None if usage_root is None else
             usage_root / GROUP / name / ("cpu.stat" if version == 2 else "cpuacct.usage"))
    group = SlotCgroup(version, dirs, freezer, usage)
    if create and _CREATED.get(group) != processes:
        try:
            _create(group, processes)
        except OSError:
            return None
        _CREATED[group] = processes
    return group


#: the slots this process made, each with the ``pids.max`` it last wrote. The warm
#: parent makes its slot's once; a forked child inherits this and only joins (the
#: writes of :func:`_create` cost a child several milliseconds each time).
_CREATED: dict[SlotCgroup, int] = {}


def forget_created() -> None:
    """Make the next :func:`slot_cgroup` write its directories and settings again
    (for a group removed since it was made)."""
    _CREATED.clear()


def _create(group: SlotCgroup, processes: int) -> None:
    for directory in group.dirs + ((group.freezer,) if group.freezer else ()):
        if group.version == 2:
            _enable_controllers(directory.parent.parent)
            directory.parent.mkdir(exist_ok=True)
            _enable_controllers(directory.parent)
        directory.mkdir(parents=True, exist_ok=True)
    for directory in group.dirs:
        files = {"cpu.shares": str(V1_SHARES), "cpu.weight": str(V2_WEIGHT),
                 "pids.max": str(processes)}
        for filename, value in files.items():
            path = directory / filename
            if path.exists():
                path.write_text(value)


def _enable_controllers(directory: Path) -> None:
    try:
        (directory / "cgroup.subtree_control").write_text("+cpu +pids")
    except OSError as exc:
        if exc.errno not in (errno.EBUSY,):  # already enabled with processes inside
            raise


@functools.cache
def _layout() -> tuple[int, tuple[Path, ...], Path | None, Path | None] | None:
    """(version, roots listing processes first, v1 freezer root, root of the CPU usage
    file) usable here, or None."""
    if os.geteuid() != 0:
        return None
    mounts = _cgroup_mounts()
    v2 = mounts.get("cgroup2")
    if v2 is not None and {"cpu", "pids"} <= _controllers(v2):
        return 2, (v2,), None, v2
    cpu = mounts.get("cpu")
    if cpu is None:
        return None
    # cpuacct's folder is joined like the others: its cpuacct.usage counts the slot's CPU.
    roots = [cpu] + [mounts[c] for c in ("pids", "cpuacct") if c in mounts]
    return 1, tuple(dict.fromkeys(roots)), mounts.get("freezer"), mounts.get("cpuacct")


def _controllers(root: Path) -> set[str]:
    try:
        return set((root / "cgroup.controllers").read_text().split())
    except OSError:
        return set()


def _cgroup_mounts() -> dict[str, Path]:
    """Mount point of each v1 controller, and of the v2 hierarchy as "cgroup2"."""
    found: dict[str, Path] = {}
    try:
        lines = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return found
    for line in lines:
        before, _, after = line.partition(" - ")
        fields, tail = before.split(), after.split()
        if len(fields) < 5 or len(tail) < 3:
            continue
        mount_point = Path(fields[4].replace("\\040", " "))
        if tail[0] == "cgroup2":
            found.setdefault("cgroup2", mount_point)
        elif tail[0] == "cgroup":
            for option in tail[2].split(","):
                if option in ("cpu", "cpuacct", "pids", "freezer"):
                    found.setdefault(option, mount_point)
    return found


def cgroup_support() -> str:
    """One sentence for the grader's log: what the slot cgroups give here."""
    layout = _layout()
    if layout is None:
        if os.geteuid() != 0:
            return ("Not running as root: no cgroup per slot, so one submission's busy "
                    "processes can slow the other slots (CPU-time limits still hold).")
        return "No usable cgroup hierarchy (cpu controller): slots share the CPU unweighted."
    version, roots, freezer, _ = layout
    kill = "cgroup.kill" if version == 2 else ("freezer" if freezer else "repeated sweeps")
    return f"cgroup v{version} per slot: equal CPU weight, pids.max, kill by {kill}."
