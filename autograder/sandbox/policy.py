"""What the sandbox applies to a worker child: its resource limits and isolation policy.

:class:`Limits` and :class:`IsolationPolicy` check their settings when they are
made, with a message naming the bad one;
:func:`autograder.sandbox.confine.enter_sandbox` applies them in the forked child.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from autograder.errors import UsageError

__all__ = ["IsolationPolicy", "Limits"]

GIB = 1 << 30
MIB = 1 << 20


@dataclass(frozen=True)
class Limits:
    """Resource limits of one worker child.

    Parameters
    ----------
    memory_bytes : int
        Address space (``RLIMIT_AS``); a larger allocation raises ``MemoryError``.
    cpu_seconds : int
        CPU time (``RLIMIT_CPU``); ``SIGXCPU`` at the limit, ``SIGKILL`` one second later.
    processes : int
        Processes and threads of the child's user (``RLIMIT_NPROC``).
    open_files : int
        File descriptors (``RLIMIT_NOFILE``).
    file_size_bytes : int
        Largest file the child may write (``RLIMIT_FSIZE``).
    output_bytes : int
        Cap on captured stdout/stderr, enforced by the worker, not here.
    disk_bytes : int
        Total size of the files in the working directory (the size of the tmpfs
        mounted over it; needs a mount namespace, see :mod:`autograder.sandbox.seccomp`).
    """

    memory_bytes: int = 4 * GIB
    cpu_seconds: int = 60
    processes: int = 64
    open_files: int = 256
    file_size_bytes: int = 64 * MIB
    output_bytes: int = 1 * MIB
    disk_bytes: int = 256 * MIB

    def __post_init__(self) -> None:
        for name in ("memory_bytes", "cpu_seconds", "processes", "open_files",
                     "file_size_bytes", "output_bytes", "disk_bytes"):
            _require_positive_int(f"limits.{name}", getattr(self, name))


@dataclass(frozen=True)
class IsolationPolicy:
    """What :func:`autograder.sandbox.confine.enter_sandbox` applies.

    Parameters
    ----------
    limits : Limits
        Resource limits.
    landlock : bool
        Enforce the Landlock ruleset (files, TCP, signals) when the kernel has it.
    network_namespace : bool
        Move into an empty network namespace; applied only when running as root.
    drop_user : bool
        Switch to uid/gid ``base_uid + slot``; applied only when running as root.
    base_uid : int
        First uid of the worker slots; slot ``k`` runs as ``base_uid + k`` so that
        concurrent children never share an ``RLIMIT_NPROC`` count.
    allowed_read : tuple of str
        Extra read-only paths (for example a shared data set).
    namespaces : bool
        Private IPC, UTS and mount namespaces and the disk quota (as an ordinary
        user, inside a user namespace when the kernel allows one).
    pid_namespace : bool
        With ``namespaces``, a PID namespace of the child's own and ``/proc``
        remounted for it, so no other process of the machine can be seen or named
        (see :mod:`autograder.sandbox.pidns`).
    seccomp : bool
        Load the seccomp filter of :func:`autograder.sandbox.seccomp.install_filter`.
    cgroup : bool
        As root, move the child into its slot's cgroup (equal CPU weight per slot,
        ``pids.max``, a kill that re-forking cannot dodge; see :mod:`autograder.sandbox.cgroups`).
    """

    limits: Limits = field(default_factory=Limits)
    landlock: bool = True
    network_namespace: bool = True
    drop_user: bool = True
    base_uid: int = 61000
    allowed_read: tuple[str, ...] = ()
    namespaces: bool = True
    pid_namespace: bool = True
    seccomp: bool = True
    cgroup: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.limits, Limits):
            raise UsageError(
                f"`policy.limits` must be a `Limits`; got {type(self.limits).__name__}."
            )
        for name in ("landlock", "network_namespace", "drop_user", "namespaces",
                     "pid_namespace", "seccomp", "cgroup"):
            if not isinstance(getattr(self, name), bool):
                value = getattr(self, name)
                raise UsageError(f"`policy.{name}` must be True or False; got {value!r}.")
        _require_positive_int("policy.base_uid", self.base_uid)
        if isinstance(self.allowed_read, (str, bytes)) or not all(
            isinstance(p, str) for p in self.allowed_read
        ):
            raise UsageError("`policy.allowed_read` must be a tuple of path strings; "
                             f"got {self.allowed_read!r}.")
        object.__setattr__(self, "allowed_read", tuple(self.allowed_read))


def _require_positive_int(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise UsageError(f"`{name}` must be a positive integer; got {value!r}.")
