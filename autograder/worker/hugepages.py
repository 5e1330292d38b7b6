"""Move the warm parent's heap into transparent huge pages, so each ``fork()`` copies less.

A fork copies one page-table entry per 4 KiB page of the parent's private memory,
and the child's exit takes every one of them down again: with numpy, scipy,
matplotlib and IPython imported that is about 100 MiB, some 25,000 entries, and
most of a trivial submission's fork and exit. ``madvise(MADV_COLLAPSE)`` (Linux
6.1) rewrites what is already in memory as 2 MiB pages, whatever the system's THP
setting; a fork then copies one entry per 2 MiB, and a child that writes into one
gets its own 4 KiB copy as before (since Linux 5.8 the kernel splits the shared
huge page for the child instead of copying all of it).

Written by hand (``ctypes``): :meth:`mmap.mmap.madvise` only works on a mapping
that Python created, and no maintained library offers ``MADV_COLLAPSE``. Where the
kernel refuses (older kernels, other systems), nothing changes but the fork's cost.
"""

from __future__ import annotations

import ctypes
import functools
from collections.abc import Callable, Iterator

MADV_COLLAPSE = 25  # <linux/mman.h>
HUGE_PAGE = 2 << 20
#: the warm parent collapses after forking this many children: the collapse costs the
#: kernel about 2.7 ms of CPU per MiB (0.15-0.2 s once), and saves each later fork and
#: exit about 3 ms (benchmarks/fork_floor.py), so only a batch this long soon pays it back
COLLAPSE_AFTER = 50


@functools.cache
def _madvise() -> Callable[[int, int, int], int] | None:
    try:
        function = ctypes.CDLL(None, use_errno=True).madvise
    except (OSError, AttributeError):  # not a C library with madvise
        return None
    function.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int]
    function.restype = ctypes.c_int
    return function  # type: ignore[no-any-return]


def _private_anonymous_ranges(maps: str = "/proc/self/maps") -> Iterator[tuple[int, int]]:
    """The huge-page-aligned parts of this process's writable anonymous mappings."""
    try:
        with open(maps) as handle:
            lines = handle.readlines()
    except OSError:  # no /proc: nothing to do
        return
    for line in lines:
        fields = line.split()
        if len(fields) < 5 or fields[1] != "rw-p":
            continue
        if len(fields) > 5 and fields[5] != "[heap]":  # a file's data or a stack: left alone
            continue
        low, high = (int(value, 16) for value in fields[0].split("-"))
        start = -(-low // HUGE_PAGE) * HUGE_PAGE
        end = high // HUGE_PAGE * HUGE_PAGE
        if end > start:
            yield start, end


def collapse() -> int:
    """Rewrite this process's anonymous memory as huge pages where the kernel can.

    Returns
    -------
    int
        Bytes of the ranges the kernel collapsed (0 where it cannot: a kernel before
        6.1, a range with a guard page or ``MADV_NOHUGEPAGE``, not Linux).
    """
    madvise = _madvise()
    if madvise is None:
        return 0
    done = 0
    for start, end in _private_anonymous_ranges():
        if madvise(start, end - start, MADV_COLLAPSE) == 0:
            done += end - start
    return done


def huge_bytes(smaps: str = "/proc/self/smaps_rollup") -> int:
    """Bytes of this process's memory now in anonymous huge pages (0 if unknown)."""
    try:
        with open(smaps) as handle:
            for line in handle:
                if line.startswith("AnonHugePages:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0
