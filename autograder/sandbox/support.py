"""What the running kernel and user allow the sandbox, probed once per process.

:func:`probe_support` finds the Landlock ABI, whether a network or user namespace
can be made and whether libseccomp and the slot cgroups are there, and says in one
sentence per missing protection what the grader goes without, for its log.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass

from autograder.sandbox import cgroups, kernel, seccomp
from autograder.sandbox.landlock import landlock_abi

__all__ = ["IsolationSupport", "probe_support"]


@dataclass(frozen=True)
class IsolationSupport:
    """What the running kernel and user allow.

    Attributes
    ----------
    landlock_abi : int
        Landlock ABI version of the kernel, 0 when Landlock is unavailable.
    is_root : bool
        Whether the process runs as root (namespace and user switch possible).
    can_unshare_net : bool
        Whether a child could create a network namespace.
    notes : tuple of str
        One sentence per missing protection, for the grader's log.
    user_namespaces : bool
        Whether a child may create a user namespace (always True for root); an
        ordinary user gets IPC, mount and network namespaces and the disk quota
        only through one.
    seccomp : bool
        Whether libseccomp is available to build the system-call filter.
    """

    landlock_abi: int
    is_root: bool
    can_unshare_net: bool
    notes: tuple[str, ...]
    user_namespaces: bool = False
    seccomp: bool = False


@functools.cache
def probe_support() -> IsolationSupport:
    """Find out which protections this machine supports (cached per process).

    The network namespace is tried in a short-lived forked child, so the caller
    is left unchanged.

    Returns
    -------
    IsolationSupport
    """
    abi = landlock_abi()
    is_root = os.geteuid() == 0
    can_unshare = _try_in_child(lambda: kernel.unshare(kernel.CLONE_NEWNET))
    userns = seccomp.user_namespaces_allowed()
    has_seccomp = seccomp.pyseccomp is not None
    notes = _support_notes(abi, is_root, can_unshare) + _syscall_notes(is_root, userns, has_seccomp)
    return IsolationSupport(abi, is_root, can_unshare, notes, userns, has_seccomp)


def _syscall_notes(is_root: bool, userns: bool, seccomp: bool) -> tuple[str, ...]:
    notes = []
    if not seccomp:
        notes.append("libseccomp is missing (Debian: libseccomp2): new sockets of other "
                     "families than TCP, keyrings and memfd files are not blocked.")
    if not is_root and not userns:
        notes.append("User namespaces are refused for this user: no IPC or mount namespace "
                     "(System V IPC is blocked by seccomp instead) and no total disk quota.")
    cgroup_note = cgroups.cgroup_support()
    if not cgroup_note.startswith("cgroup v"):
        notes.append(cgroup_note)
    return tuple(notes)


def _support_notes(abi: int, is_root: bool, can_unshare: bool) -> tuple[str, ...]:
    notes = []
    if abi == 0:
        notes.append(
            "Landlock is not available (kernel ABI 0): file and network restrictions "
            "are off; rlimits, timeouts and the network namespace still apply."
        )
    elif abi < 4:
        notes.append(f"Landlock ABI {abi} has no TCP rules (needs ABI 4): only the "
                     "network namespace blocks TCP.")
    if 0 < abi < 6:
        notes.append(f"Landlock ABI {abi} cannot scope signals (needs ABI 6): only the "
                     "separate user id stops the child from signalling the grader.")
    if not is_root:
        notes.append("Not running as root: the child keeps the grader's user id (its "
                     "network, IPC and mount namespaces come from a user namespace where "
                     "allowed); RLIMIT_NPROC is set to the limit plus the user's existing tasks.")
    elif not can_unshare:
        notes.append("A network namespace cannot be created here: only Landlock "
                     "blocks TCP.")
    return tuple(notes)


def _try_in_child(action: Callable[[], object]) -> bool:
    """Run ``action`` in a forked child; True when it returned without an error."""
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            action()
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0
