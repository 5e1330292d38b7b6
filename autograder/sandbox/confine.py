"""Isolation applied inside the forked worker child, just before student code runs.

The warm worker ("zygote") imports numpy, scipy, matplotlib and IPython once and
then ``os.fork()``s one child per submission. The child calls :func:`enter_sandbox`,
which, in this order:

1. starts a new session, so the grader can ``killpg`` the child and everything it forks,
   and, as root, joins the slot's cgroup;
2. replaces the environment (no tokens, no CI variables, not even in
   ``/proc/self/environ``) and moves into the submission's working directory;
3. sets resource limits (address space, CPU, processes, open files, file size, core);
4. as root, is in an empty network namespace (the one its warm parent made once for
   the slot, see :func:`prepare_network`, or one of its own) and switches to a user id
   of its own (``base_uid + slot``) keeping only ``CAP_DAC_READ_SEARCH``;
5. enforces a Landlock ruleset: read-only access to the Python installation and the
   system directories, full access to the working directory only, no TCP bind or
   connect, no signals or abstract UNIX sockets outside the sandbox.

The environment is built in :mod:`autograder.sandbox.environment`, the Landlock
ruleset in :mod:`autograder.sandbox.landlock` (the warm parent builds it once, see
:func:`autograder.sandbox.landlock.shared_landlock`). Steps of
:mod:`autograder.sandbox.seccomp` come in between: right after the new session,
private IPC, UTS, mount and PID namespaces (as an ordinary user inside a user
namespace; as root the child is born as the PID namespace's first process
(:func:`fork_child`), otherwise that namespace needs one more fork, after which only
its first process goes on, see :mod:`autograder.sandbox.pidns`) with a size-limited
tmpfs over the working directory and ``/proc`` remounted; just before Landlock, a
seccomp filter (no new socket of any family, no keyrings, memfd or io_uring; no
System V IPC where there is no IPC namespace).

Why this is written by hand: tools such as bubblewrap, nsjail or firejail start a
*new program*, which would throw away the warm interpreter and its imported modules;
here every step must be applied in-process to a forked Python child. ``landlockpy``
wraps the Landlock system calls, but no well-kept library combines Landlock with
rlimits, namespaces and capability dropping, so the remaining system calls (``unshare``,
``prctl``, ``capset``) are called through :mod:`ctypes` (:mod:`autograder.sandbox.kernel`).

Already-open file descriptors (the socket to the grader, the pipes for output) keep
working: neither Landlock nor the user switch affects them.

Without the user switch (not root, or ``drop_user=False``) the child shares the
grader's uid; without a PID namespace as well, Landlock does not stop it from reading
``/proc/<pid>/environ`` of the grader's processes (it blocks ptrace attach and
``/proc/<pid>/mem`` only). Start the grader's processes with a clean environment, or
make them non-dumpable (``prctl(PR_SET_DUMPABLE, 0)``), in that setting. Without a
PID namespace, command lines in ``/proc/<pid>/cmdline`` are readable by every user,
as always on Linux.
"""

from __future__ import annotations

import errno
import os
import resource
from collections.abc import Callable, Sequence
from pathlib import Path

from autograder.errors import UsageError
from autograder.sandbox import cgroups, kernel, pidns, seccomp
from autograder.sandbox.environment import clean_environment, replace_environment
from autograder.sandbox.landlock import (SharedLandlock, allow_own_proc, prepare_landlock, restrict,
                                         write_layer)
from autograder.sandbox.policy import IsolationPolicy, Limits
from autograder.sandbox.readable import coverable_folders

__all__ = ["enter_sandbox", "fork_child", "prepare_cgroup", "prepare_network"]

# <linux/prctl.h>: keep the permitted capabilities when setresuid() leaves uid 0.
PR_SET_KEEPCAPS = 8
# <linux/prctl.h>: remove one capability from the bounding set (needs CAP_SETPCAP);
# a process can never regain a capability that is not in its bounding set.
PR_CAPBSET_DROP = 24
# <linux/capability.h>: bypass read and search permission checks on files and
# directories. Kept because the Python installation may live under a directory
# that other users cannot enter (here /root, mode 700); Landlock still confines
# reads to the allowed paths.
CAP_DAC_READ_SEARCH = 2
# Highest capability number (CAP_CHECKPOINT_RESTORE, Linux 5.9+) if
# /proc/sys/kernel/cap_last_cap cannot be read.
CAP_LAST_CAP_FALLBACK = 40

# uid_t is 32 bits and (uid_t)-1 means "unchanged" to setresuid(2).
MAX_UID = 2**32 - 1


# --------------------------------------------------------------------------- entry


def fork_child(policy: IsolationPolicy) -> int:
    """``os.fork()`` the child that will call :func:`enter_sandbox` with ``policy``.

    As root, with a PID namespace in the policy, the child is born as the first
    process of a namespace of its own, so that it needs no relay process (see
    :mod:`autograder.sandbox.pidns`); otherwise a plain fork.
    """
    return pidns.fork(new_namespace=policy.namespaces and policy.pid_namespace
                      and os.geteuid() == 0)


def enter_sandbox(
    policy: IsolationPolicy,
    workdir: Path,
    *,
    slot: int,
    exclude: Sequence[Path] = (),
    shared: SharedLandlock | None = None,
) -> tuple[str, ...]:
    """Confine the calling process; call it in the forked child, before student code.

    Parameters
    ----------
    policy : IsolationPolicy
        What to apply.
    workdir : Path
        The submission's directory: the only place the child may write.
    slot : int
        Index of the worker slot; the child runs as ``policy.base_uid + slot``.
    exclude : sequence of Path
        Trees the child must not read (repository root, assignment folder).
    shared : SharedLandlock, optional
        The Landlock ruleset the warm parent built once (see
        :func:`autograder.sandbox.landlock.shared_landlock`), used when ``workdir`` lies
        directly in its work root; the child then adds a small layer of its own that
        confines writes to ``workdir``. Without it the child builds the whole ruleset
        itself.

    Returns
    -------
    tuple of str
        One short note per step, saying what was applied or why it was skipped.

    Raises
    ------
    UsageError
        If ``slot`` is not a non-negative integer or ``workdir`` is not a directory.
    OSError
        If a resource limit cannot be set: the limits are the floor of the sandbox.

    Notes
    -----
    Must run in a single-threaded process (a fresh fork): Landlock before ABI 8
    restricts only the calling thread. A step the environment refuses (for example
    ``EPERM`` in an unprivileged container) is skipped and noted, never raised.
    """
    workdir = _check_arguments(policy, workdir, slot)
    notes: list[str] = []
    _attempt(notes, "new session", os.setsid)
    # Both before the namespaces: the cgroup is joined while the slot's folders can be
    # reached, and the user's processes are counted while /proc shows them all.
    _join_cgroup(policy, slot, notes)
    processes = _process_allowance(policy)
    private_ipc = _apply_namespaces(policy, workdir, exclude, notes)
    notes.append(replace_environment(clean_environment(workdir)))
    os.chdir(workdir)
    if shared is not None and shared.serves(policy, workdir, exclude):
        notes.extend(shared.notes)
        ruleset = shared.ruleset
        writes = None if ruleset is None else write_layer(workdir, notes)
        if ruleset is not None and policy.namespaces and policy.pid_namespace:
            allow_own_proc(ruleset)
    else:
        ruleset, writes = prepare_landlock(policy, workdir, exclude, notes), None
    notes.append(_apply_limits(policy.limits, processes))
    _apply_identity(policy, workdir, policy.base_uid + slot, notes)
    if policy.seccomp:
        _attempt(notes, "seccomp", lambda: seccomp.install_filter(block_sysv_ipc=not private_ipc))
    else:
        notes.append("seccomp off by policy")
    if ruleset is not None:
        _attempt(notes, "landlock", lambda: restrict(ruleset))
    if writes is not None:
        _attempt(notes, "landlock write layer",
                 lambda: restrict(writes, "landlock write layer"))
    return tuple(notes)


def _check_arguments(policy: IsolationPolicy, workdir: Path, slot: int) -> Path:
    if isinstance(slot, bool) or not isinstance(slot, int) or slot < 0:
        raise UsageError(f"`slot` must be a non-negative integer; got {slot!r}.")
    if policy.base_uid + slot >= MAX_UID:
        raise UsageError(f"`policy.base_uid + slot` must be below {MAX_UID}; "
                         f"got {policy.base_uid + slot}.")
    resolved = Path(workdir).resolve()
    if not resolved.is_dir():
        raise UsageError(f"`workdir` must be an existing directory; got {str(workdir)!r}.")
    return resolved


def _attempt(notes: list[str], label: str, step: Callable[[], str | None]) -> None:
    """Run one step; note its result, or note and skip it if the system refuses."""
    try:
        result = step()
    except OSError as exc:
        notes.append(f"{label} skipped: {exc.strerror or exc}")
    else:
        notes.append(result or label)


def _apply_namespaces(policy: IsolationPolicy, workdir: Path, exclude: Sequence[Path],
                      notes: list[str]) -> bool:
    """Private IPC/UTS/mount (and PID) namespaces and the disk quota; True if IPC is private.

    An ordinary user also gets an empty network namespace here, inside the same
    user namespace (root gets one in :func:`_apply_identity`). Excluded folders
    that hold nothing the child needs are covered by empty mounts.
    """
    if not policy.namespaces:
        notes.append("IPC/mount/PID namespaces and disk quota off by policy")
        return False
    result = seccomp.private_namespaces(
        workdir, quota_bytes=policy.limits.disk_bytes,
        network=policy.network_namespace and os.geteuid() != 0,
        hide=coverable_folders(exclude, workdir, policy), pid=policy.pid_namespace)
    notes.extend(result.notes)
    return result.ipc


# ------------------------------------------------------- cgroup and network namespace


def _join_cgroup(policy: IsolationPolicy, slot: int, notes: list[str]) -> None:
    """As root, enter the slot's cgroup (before the user switch: it needs root)."""
    if not policy.cgroup or os.geteuid() != 0:
        notes.append("slot cgroup " + ("off by policy" if not policy.cgroup
                                       else "skipped: not running as root"))
        return
    group = cgroups.slot_cgroup(slot, processes=policy.limits.processes)
    if group is None:
        notes.append("slot cgroup skipped: no usable cgroup hierarchy")
        return
    _attempt(notes, "slot cgroup", lambda: _join(group, slot, policy.limits.processes))


def _join(group: cgroups.SlotCgroup, slot: int, processes: int) -> str:
    try:
        group.join()
    except FileNotFoundError:  # removed since the warm parent made it: make it again
        cgroups.forget_created()
        group = cgroups.slot_cgroup(slot, processes=processes) or group
        group.join()
    return f"slot cgroup v{group.version}: {', '.join(str(d) for d in group.dirs)}"


def prepare_cgroup(policy: IsolationPolicy, slot: int) -> None:
    """Make and configure the slot's cgroup in the warm parent, once, before it forks.

    Every child then only joins it (see :func:`_join_cgroup`); nothing happens for
    an ordinary user or a policy without cgroups.
    """
    if policy.cgroup and os.geteuid() == 0:
        cgroups.slot_cgroup(slot, processes=policy.limits.processes)


#: as root, the network namespace the warm parent came from (an open descriptor), once
#: :func:`prepare_network` moved it into the empty one its children share
_HOST_NETWORK: list[int | None] = [None]


def prepare_network(policy: IsolationPolicy) -> None:
    """As root, move the warm parent into an empty network namespace, once, before it forks.

    Every child is then born in it and needs no ``unshare`` of its own: about 0.5 ms
    of the child's CPU and 1 ms of the kernel's teardown per submission
    (``benchmarks/sandbox_costs.py``). Sharing it leaks nothing from one student to the
    next: a slot runs one child at a time, every process of a submission is killed
    before the next starts (:func:`autograder.sandbox.reaper.sweep_slot`), and no child keeps
    the capabilities to configure the namespace (only ``lo``, down). A child whose
    policy wants the network returns to the namespace the parent came from. Nothing
    happens for an ordinary user, whose children make their own inside a user namespace.
    """
    if not policy.network_namespace or os.geteuid() != 0 or _HOST_NETWORK[0] is not None:
        return
    try:
        host = os.open("/proc/self/ns/net", os.O_RDONLY | os.O_CLOEXEC)
    except OSError:  # no /proc: each child unshares its own
        return
    try:
        kernel.unshare(kernel.CLONE_NEWNET)
    except OSError:
        os.close(host)
        return
    _HOST_NETWORK[0] = host


def _network(policy: IsolationPolicy, notes: list[str]) -> None:
    """As root, in the child: the empty network namespace, or the host's if the policy says."""
    host, _HOST_NETWORK[0] = _HOST_NETWORK[0], None
    if host is None:
        if policy.network_namespace:
            _attempt(notes, "network namespace", lambda: kernel.unshare(kernel.CLONE_NEWNET))
        else:
            notes.append("network namespace off by policy")
        return
    try:  # the child keeps no handle on the host's namespace
        if policy.network_namespace:
            notes.append("network namespace: the slot's empty one (made once by the warm parent)")
        else:
            _attempt(notes, "network namespace off by policy, host network restored",
                     lambda: kernel.setns(host, kernel.CLONE_NEWNET))
    finally:
        os.close(host)


# -------------------------------------------------------------------------- rlimits


def _apply_limits(limits: Limits, processes: int) -> str:
    """Set every rlimit with soft = hard so the child cannot raise it back.

    The CPU hard limit is one second above the soft one: ``SIGXCPU`` first (a
    catchable warning), then ``SIGKILL``.
    """
    wanted = [
        ("RLIMIT_AS", resource.RLIMIT_AS, limits.memory_bytes, limits.memory_bytes),
        ("RLIMIT_CPU", resource.RLIMIT_CPU, limits.cpu_seconds, limits.cpu_seconds + 1),
        ("RLIMIT_NPROC", resource.RLIMIT_NPROC, processes, processes),
        ("RLIMIT_NOFILE", resource.RLIMIT_NOFILE, limits.open_files, limits.open_files),
        ("RLIMIT_FSIZE", resource.RLIMIT_FSIZE, limits.file_size_bytes, limits.file_size_bytes),
        ("RLIMIT_CORE", resource.RLIMIT_CORE, 0, 0),
    ]
    for name, which, soft, hard in wanted:
        _set_limit(name, which, soft, hard)
    return "rlimits: " + ", ".join(f"{name[7:].lower()}={soft}" for name, _, soft, _ in wanted)


def _set_limit(name: str, which: int, soft: int, hard: int) -> None:
    """Lower a limit; never above the current hard limit (raising needs privileges)."""
    current_hard = resource.getrlimit(which)[1]
    if current_hard != resource.RLIM_INFINITY:
        soft, hard = min(soft, current_hard), min(hard, current_hard)
    try:
        resource.setrlimit(which, (soft, hard))
    except (OSError, ValueError) as exc:
        code = getattr(exc, "errno", None) or errno.EPERM
        raise OSError(code, f"could not set {name} to {soft}/{hard}: {exc}") from exc


def _process_allowance(policy: IsolationPolicy) -> int:
    """RLIMIT_NPROC counts every task of the real uid, not only the child's.

    When the child gets a uid of its own the count starts at zero; otherwise the
    user's existing processes and threads are added to the limit.
    """
    if os.geteuid() == 0 and policy.drop_user:
        return policy.limits.processes
    return policy.limits.processes + _count_tasks(os.getuid())


def _count_tasks(uid: int) -> int:
    total = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            status = Path(entry.path, "status").read_text()
        except OSError:  # the process exited meanwhile
            continue
        fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
        if int(fields["Uid"].split()[0]) == uid:
            total += int(fields["Threads"])
    return total


# ---------------------------------------------------------- namespace, user and caps


def _apply_identity(policy: IsolationPolicy, workdir: Path, uid: int, notes: list[str]) -> None:
    """As root: an empty network namespace, then a user id of the slot's own."""
    if os.geteuid() != 0:
        notes.append("user switch skipped: not running as root (a network namespace only inside a "
                     "user namespace, see the namespaces note)")
        return
    _network(policy, notes)
    if policy.drop_user:
        _attempt(notes, "user switch", lambda: _drop_user(workdir, uid))
    else:
        notes.append("user switch off: RLIMIT_NPROC does not bind root")


def _drop_user(workdir: Path, uid: int) -> str:
    """Become ``uid``/``uid`` with CAP_DAC_READ_SEARCH as the only capability."""
    _chown_tree(workdir, uid)
    _drop_bounding_set(keep=CAP_DAC_READ_SEARCH)
    kernel.prctl(PR_SET_KEEPCAPS, 1)  # else setresuid() below clears the permitted set
    os.setgroups([])
    os.setresgid(uid, uid, uid)
    os.setresuid(uid, uid, uid)
    kernel.capset(1 << CAP_DAC_READ_SEARCH)
    return f"user: uid and gid {uid}, no groups, capabilities: CAP_DAC_READ_SEARCH"


def _chown_tree(top: Path, uid: int) -> None:
    """Give the working directory to the child's user (links are not followed)."""
    os.chown(top, uid, uid, follow_symlinks=False)
    for directory, subdirs, files in os.walk(top):
        for name in subdirs + files:
            os.chown(os.path.join(directory, name), uid, uid, follow_symlinks=False)


def _drop_bounding_set(*, keep: int) -> None:
    for cap in range(_last_capability() + 1):
        if cap != keep:
            kernel.prctl(PR_CAPBSET_DROP, cap)


def _last_capability() -> int:
    try:
        return int(Path("/proc/sys/kernel/cap_last_cap").read_text())
    except (OSError, ValueError):
        return CAP_LAST_CAP_FALLBACK
