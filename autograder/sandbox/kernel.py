"""The system calls the sandbox needs that Python 3.11 does not offer, through :mod:`ctypes`.

``unshare``, ``setns``, ``mount``, ``prctl`` and ``capset`` (``os.unshare`` and ``os.setns``
came in Python 3.12; the other two are not in :mod:`os` at all), the C library
they are called through, and the flags of ``<sched.h>`` they take. Each call
raises :class:`OSError` with the system's message when the kernel refuses it.
"""

from __future__ import annotations

import ctypes
import functools
import os

__all__ = ["CLONE_NEWIPC", "CLONE_NEWNET", "CLONE_NEWNS", "CLONE_NEWUSER", "CLONE_NEWUTS",
           "capset", "check", "child_subreaper", "libc", "mount", "prctl", "setns", "unshare"]

# <sched.h>: flags of unshare(2) and setns(2). CLONE_NEWNET makes a new, empty
# network namespace (only ``lo``, down).
CLONE_NEWNS = 0x00020000
CLONE_NEWUTS = 0x04000000
CLONE_NEWIPC = 0x08000000
CLONE_NEWUSER = 0x10000000
CLONE_NEWNET = 0x40000000
# <linux/prctl.h>: whether a process adopts the orphans among its descendants
PR_SET_CHILD_SUBREAPER = 36
PR_GET_CHILD_SUBREAPER = 37
# <linux/capability.h>: header version of capset(2) with two 32-bit data words.
LINUX_CAPABILITY_VERSION_3 = 0x20080522


class _CapHeader(ctypes.Structure):
    """struct __user_cap_header_struct of <linux/capability.h>."""

    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]


class _CapData(ctypes.Structure):
    """struct __user_cap_data_struct: one 32-bit word of each capability set."""

    _fields_ = [
        ("effective", ctypes.c_uint32),
        ("permitted", ctypes.c_uint32),
        ("inheritable", ctypes.c_uint32),
    ]


def capset(mask: int) -> None:
    """Set effective = permitted = ``mask`` and inheritable = 0 for this thread."""
    header = _CapHeader(LINUX_CAPABILITY_VERSION_3, 0)
    data = (_CapData * 2)()
    for word in range(2):
        bits = (mask >> (32 * word)) & 0xFFFFFFFF
        data[word].effective = data[word].permitted = bits
    check("capset", libc().capset(ctypes.byref(header), data))


def unshare(flags: int) -> None:
    # Python 3.11 has no os.unshare (added in 3.12).
    check("unshare", libc().unshare(flags))


def setns(fd: int, kind: int) -> None:
    # Python 3.11 has no os.setns (added in 3.12).
    check("setns", libc().setns(fd, kind))


def mount(source: str | None, target: str, fstype: str | None, flags: int,
          data: str | None) -> None:
    # Python has no os.mount.
    def c_str(text: str | None) -> bytes | None:
        return None if text is None else os.fsencode(text)

    call = libc().mount
    call.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong,
                     ctypes.c_char_p]
    check("mount", call(c_str(source), c_str(target), c_str(fstype), flags, c_str(data)))


def prctl(option: int, arg: int) -> None:
    # prctl(2) is variadic: pass every argument as a full unsigned long.
    args = [ctypes.c_ulong(value) for value in (arg, 0, 0, 0)]
    check("prctl", libc().prctl(ctypes.c_int(option), *args))


def child_subreaper(on: bool) -> bool:
    """Set whether this process adopts its descendants' orphans; return what it was."""
    was = ctypes.c_int(0)
    check("prctl", libc().prctl(ctypes.c_int(PR_GET_CHILD_SUBREAPER), ctypes.byref(was),
                                ctypes.c_ulong(0), ctypes.c_ulong(0), ctypes.c_ulong(0)))
    prctl(PR_SET_CHILD_SUBREAPER, int(on))
    return bool(was.value)


@functools.cache
def libc() -> ctypes.CDLL:
    """The C library of this process, setting ``errno`` for :func:`check`."""
    return ctypes.CDLL(None, use_errno=True)


def check(name: str, result: int) -> None:
    """Raise the system's error if the C call ``name`` returned -1."""
    if result == -1:
        code = ctypes.get_errno()
        raise OSError(code, f"{name}: {os.strerror(code)}")
