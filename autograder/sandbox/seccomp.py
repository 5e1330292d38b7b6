"""System-call level confinement of the worker child: namespaces, disk quota, seccomp.

:func:`autograder.sandbox.confine.enter_sandbox` calls, in the forked child:

1. :func:`private_namespaces` early, while the child may still mount: new IPC,
   UTS and mount namespaces (as root directly; as an ordinary user inside a new
   user namespace when the kernel allows it), and a size-limited ``tmpfs`` over
   the working directory. Everything System V IPC and POSIX message queues hold
   then lives in a namespace that dies with the child's last process, and the
   files a submission writes are bounded *in total* (``RLIMIT_FSIZE`` bounds each
   file only) and vanish with the namespace.
2. :func:`install_filter` last: a seccomp filter that makes ``socket()`` and
   ``socketpair()`` fail with ``EPERM`` for every family (UNIX pathname and
   abstract, UDP, MPTCP, raw, ping, netlink, ...), keeps the keyrings, ``memfd``
   files and ``io_uring`` out of reach, keeps every process in the child's process
   group (no ``setsid``/``setpgid``), and, where no IPC namespace could be
   made, System V IPC and POSIX message queues as well. Sockets that are already
   open (the child's channel to the grader) keep working: seccomp filters new
   system calls, not descriptors.

Why a library and ``ctypes``: the filter is compiled by libseccomp (Debian's
``libseccomp2``) through ``pyseccomp``, a ctypes binding with the API of
libseccomp's own Python bindings (those are not on PyPI); writing BPF by hand would
mean re-doing libseccomp's architecture checks (x32 and i386 system calls on x86-64
are refused by its bad-architecture action, so ``socketcall(2)`` through
``int 0x80`` cannot dodge the rules). Python 3.11 has no ``os.unshare`` and no
``mount``, so those two are called through :mod:`ctypes` (``unshare`` and the C
library in :mod:`autograder.sandbox.kernel`).
"""

from __future__ import annotations

import errno
import functools
import os
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autograder.sandbox import kernel, pidns
from autograder.sandbox.kernel import (
    CLONE_NEWIPC,
    CLONE_NEWNET,
    CLONE_NEWNS,
    CLONE_NEWUSER,
    CLONE_NEWUTS,
)

try:  # pyseccomp needs libseccomp.so.2 (Linux only)
    import pyseccomp
except (ImportError, OSError):  # pragma: no cover - a Linux dependency
    pyseccomp = None  # type: ignore[assignment]

__all__ = ["NamespaceResult", "install_filter", "prepare_filters", "private_namespaces",
           "user_namespaces_allowed"]

# <sys/mount.h>
MS_RDONLY = 0x1
MS_NOSUID = 0x2
MS_NODEV = 0x4
MS_NOEXEC = 0x8
MS_REC = 0x4000
MS_PRIVATE = 1 << 18
MNT_DETACH = 2
# <linux/prctl.h>
PR_GET_DUMPABLE = 3
PR_SET_DUMPABLE = 4

#: refused for every child: new sockets of any family (the grader's channel is
#: already open), kernel keyrings (shared by every process of a user, they outlive
#: the child), memfd files (their pages escape RLIMIT_AS) and io_uring (it can open
#: sockets and files without the system calls above, IORING_OP_SOCKET since 5.19).
#: Also ``setsid`` and ``setpgid``: the child made its own session before the filter,
#: and every process it starts must stay in that process group, because killing a
#: process group is atomic against ``fork`` (a fork that races a group signal is
#: restarted and dies) while a sweep through /proc can always be one generation
#: late. Nothing the worker runs after the sandbox (IPython, numpy, matplotlib)
#: needs any of these; ``multiprocessing`` pools use pipes, but
#: ``multiprocessing.Pipe()`` (duplex) and ``Popen(start_new_session=True)`` fail.
ALWAYS_BLOCKED = (
    "socket", "socketpair",
    "add_key", "request_key", "keyctl",
    "memfd_create", "memfd_secret",
    "io_uring_setup", "io_uring_enter", "io_uring_register",
    "setsid", "setpgid",
)
#: refused when the child has no IPC namespace of its own: these objects would
#: outlive the child and be visible to the next submission of the same user.
SYSV_IPC = ("shmget", "msgget", "semget", "mq_open")


@dataclass(frozen=True)
class NamespaceResult:
    """What :func:`private_namespaces` achieved.

    Attributes
    ----------
    ipc : bool
        The child has an IPC namespace of its own (System V IPC and POSIX
        message queues die with it).
    quota_bytes : int
        Size of the tmpfs now mounted over the working directory; 0 when none
        could be mounted (then only ``RLIMIT_FSIZE`` bounds the files).
    notes : tuple of str
        One sentence per step, for the result's sandbox notes.
    """

    ipc: bool
    quota_bytes: int
    notes: tuple[str, ...]


def private_namespaces(workdir: Path, *, quota_bytes: int, network: bool = False,
                       hide: Sequence[Path] = (), pid: bool = False) -> NamespaceResult:
    """Give the calling (single-threaded, forked) process private namespaces.

    As root: ``unshare(IPC | UTS | mount)``. As an ordinary user: the same inside a
    new user namespace mapping the user to itself, after which every capability of
    that namespace is dropped again. Then a tmpfs of ``quota_bytes`` replaces the
    working directory, holding a copy of what the grader put there.

    Parameters
    ----------
    workdir : Path
        The submission's working directory (resolved, existing).
    quota_bytes : int
        Total size of the files the child may keep in ``workdir``.
    network : bool
        Also an empty network namespace (only ``lo``, down): a second wall behind
        the seccomp filter. Root's children get theirs in :mod:`autograder.sandbox.confine`.
    hide : sequence of Path
        Folders to cover with an empty read-only tmpfs in the child's mount
        namespace (the checks, the repository, other submissions): Landlock
        refuses reading them but not ``stat``, so without this a child could
        still learn which files exist there, their sizes and times.
    pid : bool
        Also a PID namespace, with ``/proc`` remounted for it: unless the caller was
        born as the first process of one (:func:`autograder.sandbox.pidns.fork`), it
        forks its first process, and only that one returns (see :mod:`autograder.sandbox.pidns`).

    Returns
    -------
    NamespaceResult
        What was applied; a step the kernel refuses is noted, never raised.
    """
    flags = CLONE_NEWIPC | CLONE_NEWUTS | CLONE_NEWNS | (CLONE_NEWNET if network else 0)
    is_root = os.geteuid() == 0
    notes: list[str] = []
    try:
        pid = _unshare(flags, pid, notes)
    except OSError as exc:
        why = "" if is_root else " (user namespaces refused for this user)"
        return NamespaceResult(False, 0, (
            f"IPC/mount namespaces skipped{why}: {exc.strerror or exc}; System V IPC "
            "and message queues blocked by seccomp instead; no disk quota beyond "
            "RLIMIT_FSIZE per file; " + pidns.OFF,))
    notes.insert(0, "namespaces: IPC, UTS, mount" + (", network" if network else "")
                 + (", PID" if pid else "") + ("" if is_root else " (in a user namespace)"))
    if pid and not pidns.born_as_init():
        pidns.split_off_init()  # from here on, the namespace's first process
    try:
        _mount_quota(workdir, quota_bytes)
    except OSError as exc:
        notes.append(f"disk quota skipped: {exc.strerror or exc}")
        quota_bytes = 0
    else:
        notes.append(f"disk quota: tmpfs of {quota_bytes} bytes over the working directory")
    if hide:
        try:
            for folder in hide:
                kernel.mount("tmpfs", str(folder), "tmpfs",
                       MS_RDONLY | MS_NOSUID | MS_NODEV | MS_NOEXEC, "size=4k,nr_inodes=2,mode=0555")
        except OSError as exc:
            notes.append(f"covering excluded folders skipped at {folder}: {exc.strerror or exc}")
        else:
            notes.append(f"excluded folders covered by empty mounts: {len(hide)}")
    if pid:
        try:
            notes.append(pidns.mount_proc())
        except OSError as exc:
            notes.append(f"/proc not remounted ({exc.strerror or exc}): {pidns.OFF}")
    if not is_root:
        _drop_namespace_capabilities()
    return NamespaceResult(True, quota_bytes, tuple(notes))


def _unshare(flags: int, pid: bool, notes: list[str]) -> bool:
    """New namespaces of ``flags`` (in a new user namespace unless root), with a PID
    namespace if ``pid`` and the kernel allows one; True when it did."""
    enter = kernel.unshare if os.geteuid() == 0 else _enter_user_namespace
    if pid and pidns.born_as_init():  # its warm parent made it (pidns.fork)
        enter(flags)
        return True
    if pid:
        try:
            enter(flags | pidns.CLONE_NEWPID)
            return True
        except OSError as exc:
            notes.append(f"PID namespace skipped ({exc.strerror or exc}): {pidns.OFF}")
    enter(flags)
    return False


def _enter_user_namespace(flags: int) -> None:
    """New user namespace (uid and gid mapped to themselves) plus ``flags``."""
    uid, gid = os.getuid(), os.getgid()
    kernel.unshare(CLONE_NEWUSER | flags)
    # A process that changed its ids (a grader started through su or setuid) is not
    # dumpable, which makes its /proc/self files root's: writable again only while
    # dumpable, then put back as it was.
    libc = kernel.libc()
    dumpable = libc.prctl(PR_GET_DUMPABLE, 0, 0, 0, 0)
    if dumpable == 0:
        kernel.check("prctl", libc.prctl(PR_SET_DUMPABLE, 1, 0, 0, 0))
    try:
        Path("/proc/self/setgroups").write_text("deny")  # required before gid_map
        Path("/proc/self/uid_map").write_text(f"{uid} {uid} 1")
        Path("/proc/self/gid_map").write_text(f"{gid} {gid} 1")
    finally:
        if dumpable == 0:
            libc.prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)


def _mount_quota(workdir: Path, quota_bytes: int) -> None:
    """Mount a tmpfs of ``quota_bytes`` over ``workdir`` and copy its files in.

    The old directory stays reachable through a descriptor opened before the mount
    (``/proc/self/fd/N`` names the covered directory), so the grader's files are
    copied from there. Mounts are made private first so that nothing propagates
    back to the grader's namespace.
    """
    kernel.mount(None, "/", None, MS_REC | MS_PRIVATE, None)
    old = os.open(workdir, os.O_RDONLY | os.O_DIRECTORY)
    try:
        options = f"size={quota_bytes},nr_inodes=65536,mode=0700"
        kernel.mount("tmpfs", str(workdir), "tmpfs", MS_NOSUID | MS_NODEV | MS_NOEXEC, options)
        try:
            os.chown(workdir, os.getuid(), os.getgid())
            shutil.copytree(f"/proc/self/fd/{old}", workdir, symlinks=True, dirs_exist_ok=True)
        except (OSError, shutil.Error) as exc:  # e.g. the public data exceed the quota
            kernel.check("umount2", kernel.libc().umount2(os.fsencode(workdir), MNT_DETACH))
            raise OSError(errno.ENOSPC, f"the working directory does not fit: {exc}") from exc
    finally:
        os.close(old)


def _drop_namespace_capabilities() -> None:
    """An ordinary user holds every capability in its new user namespace; drop them."""
    kernel.capset(0)


def install_filter(*, block_sysv_ipc: bool) -> str:
    """Load the seccomp filter into the calling process (and its future children).

    Parameters
    ----------
    block_sysv_ipc : bool
        Also refuse ``shmget``, ``msgget``, ``semget`` and ``mq_open`` (when the
        child has no IPC namespace of its own).

    Returns
    -------
    str
        A note naming what is refused.

    Raises
    ------
    OSError
        If libseccomp is missing or the kernel refuses the filter.
    """
    if pyseccomp is None:
        raise OSError(errno.ENOSYS, "libseccomp is not available (install libseccomp2)")
    rules, known = _filter(block_sysv_ipc)
    rules.load()  # sets no_new_privs first (libseccomp's default)
    return "seccomp: EPERM for " + ", ".join(known)


def prepare_filters() -> None:
    """Build both filters now (the warm parent, before it forks): a child then only loads
    the one it inherited, which saves it a third of a millisecond."""
    if pyseccomp is not None:
        try:
            for block in (False, True):
                _filter(block)
        except OSError:  # the child meets it again and notes it
            pass


@functools.lru_cache(maxsize=2)
def _filter(block_sysv_ipc: bool) -> tuple[Any, tuple[str, ...]]:
    """The filter's rules, not yet loaded, and the system calls it names."""
    names = ALWAYS_BLOCKED + (SYSV_IPC if block_sysv_ipc else ())
    rules = pyseccomp.SyscallFilter(pyseccomp.ALLOW)
    known = []
    for name in names:
        try:
            rules.add_rule(pyseccomp.ERRNO(errno.EPERM), name)
        except (OSError, ValueError):  # a system call this architecture does not have
            continue
        known.append(name)
    return rules, tuple(known)


@functools.cache
def user_namespaces_allowed() -> bool:
    """Whether this user may create a user namespace (tried in a forked child)."""
    if os.geteuid() == 0:
        return True
    pid = os.fork()
    if pid == 0:
        try:
            _enter_user_namespace(CLONE_NEWIPC | CLONE_NEWNS)
            os._exit(0)
        except BaseException:
            os._exit(1)
    _, status = os.waitpid(pid, 0)
    return os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0

