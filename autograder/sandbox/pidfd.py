"""Signals through pidfds: a process is signalled by a handle on it, never by its number.

A number read from a listing (``cgroup.procs``, ``/proc``) may belong to another
process by the time the signal is sent, once the first holder has exited and been
reaped, and the kernel hands numbers out again (``pid_max`` may be as low as 32768).
A pidfd names one process; a signal through it reaches that process or, once it is
reaped, nobody. The slot cgroup's sweep (:mod:`autograder.sandbox.cgroups`) and the
grader's kills of a child and what it left behind use these.
"""

from __future__ import annotations

import functools
import os
import signal
from typing import Callable

__all__ = ["PIDFD_SIGNAL_PROCESS_GROUP", "pidfd_kill", "pidfd_open", "pidfd_unreaped",
           "pidfds_supported", "signal_listed", "still_killed"]

#: ``pidfd_send_signal`` flag (Linux 6.9): signal the process group that the pidfd's
#: process leads, found by the kernel's pid object rather than by number
PIDFD_SIGNAL_PROCESS_GROUP = 4


@functools.cache
def pidfds_supported() -> bool:
    """Whether this kernel has pidfds (Linux 5.3+) and Python exposes them."""
    try:
        os.close(os.pidfd_open(os.getpid()))
    except (AttributeError, OSError):
        return False
    return True


def pidfd_open(pid: int) -> int | None:
    """A pidfd of the process that has number ``pid`` now; None when there is none."""
    try:
        return os.pidfd_open(pid)
    except ProcessLookupError:
        return None


def pidfd_kill(fd: int, *, group: bool = False) -> bool:
    """SIGKILL through ``fd`` (with ``group``: its process group); False when nobody was left.

    Without ``group``, a zombie not yet reaped still counts as signalled. With
    ``group``, a kernel before Linux 6.9 raises ``OSError`` (``EINVAL``).
    """
    try:
        flags = PIDFD_SIGNAL_PROCESS_GROUP if group else 0
        signal.pidfd_send_signal(fd, signal.SIGKILL, None, flags)
    except ProcessLookupError:
        return False
    return True


def pidfd_unreaped(fd: int) -> bool:
    """Whether the process of ``fd`` still exists (running, or a zombie not yet reaped)."""
    try:
        signal.pidfd_send_signal(fd, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # it exists; this process may not signal it
        return True
    return True


def signal_listed(listing: Callable[[], set[int]], killed: dict[int, int]) -> None:
    """SIGKILL every process ``listing()`` names; record each one's pidfd in ``killed``.

    The numbers are listed, a pidfd is opened for each, and the list is read again:
    a pidfd opened on a number that is still listed names a listed process (had the
    first holder of the number been reaped in between, the signal through its pidfd
    reaches nobody, and the newcomer is met by the next round). Processes already
    in ``killed`` are not signalled again. Without pidfds (Linux before 5.3) each
    listed number is signalled, which is as good as the listing is fresh.
    """
    if not pidfds_supported():
        for pid in listing():
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        return
    opened: dict[int, int] = {}
    unopened: list[int] = []  # no pidfd to be had (out of descriptors): by number
    for pid in listing():
        if not still_killed(killed, pid):
            try:
                fd = pidfd_open(pid)
            except OSError:
                unopened.append(pid)
                continue
            if fd is not None:
                opened[pid] = fd
    members = listing()
    for pid, fd in opened.items():
        if pid in members and pidfd_kill(fd):
            killed[pid] = fd
        else:
            os.close(fd)
    for pid in unopened:
        if pid in members:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


def still_killed(killed: dict[int, int], pid: int) -> bool:
    """``pid`` names a process this sweep killed (exiting, it cannot fork any more)."""
    fd = killed.get(pid)
    if fd is None:
        return False
    if pidfd_unreaped(fd):
        return True
    os.close(killed.pop(pid))  # reaped: the number now names another process
    return False
