"""Temporary folders that do not outlive their owner, even one that was killed.

A grader stopped by ``SIGKILL`` (``kill -9``, the kernel's out-of-memory killer, a CI
job's time-out) runs no clean-up code, so its slot folder (the warm worker's home
and every submission's working directory in it) would stay in ``/tmp`` for ever.
Each folder made here holds a lock file on which its owner keeps an exclusive
``flock`` for the folder's whole life. The kernel releases that lock when the owner
dies, however it dies, so the next owner of a folder of the same kind removes every
folder whose lock it can take.

Written by hand: :mod:`tempfile` removes nothing its owner did not remove, and
pytest's numbered folders (``_pytest.pathlib``) are private API, keyed on process
ids that the kernel reuses.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import stat
import tempfile
import time
from pathlib import Path

#: the lock file inside every owned folder
LOCK_NAME = ".owner.lock"
#: a lock file younger than this is never judged: its folder's owner may be between
#: creating the file and locking it
GRACE_SECONDS = 60.0


class OwnedFolder:
    """A fresh private folder, locked by this process until :meth:`remove`."""

    def __init__(self, *, prefix: str, parent: Path | None = None) -> None:
        self.path = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
        self._fd = os.open(self.path / LOCK_NAME,
                           os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC,
                           0o600)
        fcntl.flock(self._fd, fcntl.LOCK_EX)
        remove_abandoned(self.path.parent, prefix=prefix)

    def disown(self) -> None:
        """In a process forked from the owner: close this process's copy of the lock.

        The lock is the open file's (``flock``), shared with the copy a fork makes, so
        a forked process that kept it would hold the folder as long as it lives. The
        owner keeps the folder and its lock; :meth:`remove` does nothing after this.
        """
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    def remove(self) -> None:
        """Remove the folder, then let go of its lock (safe to call twice)."""
        if self._fd < 0:
            return
        shutil.rmtree(self.path, ignore_errors=True)
        os.close(self._fd)
        self._fd = -1


def remove_abandoned(parent: Path, *, prefix: str) -> list[Path]:
    """Remove the folders ``parent/<prefix>*`` of this user whose owner is gone.

    A folder counts as abandoned only when it holds a lock file of this user, older
    than :data:`GRACE_SECONDS`, that nobody holds a lock on. Folders without a lock
    file (made by an older version, or by someone else) are left alone.

    Returns
    -------
    list of Path
        The folders removed.
    """
    removed: list[Path] = []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return removed
    for entry in entries:
        if not entry.name.startswith(prefix):
            continue
        try:
            info = entry.stat(follow_symlinks=False)
        except OSError:
            continue
        if stat.S_ISDIR(info.st_mode) and info.st_uid == os.geteuid():
            folder = Path(entry.path)
            if _remove_if_abandoned(folder):
                removed.append(folder)
    return removed


def _remove_if_abandoned(folder: Path) -> bool:
    try:
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:  # no lock file, a link in its place, or gone meanwhile
        return False
    try:
        info = os.fstat(fd)
        if (not stat.S_ISREG(info.st_mode) or info.st_uid != os.geteuid()
                or time.time() - info.st_mtime < GRACE_SECONDS):
            return False
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: its owner is alive
            return False
        shutil.rmtree(folder, ignore_errors=True)
        return True
    finally:
        os.close(fd)


__all__ = ["GRACE_SECONDS", "LOCK_NAME", "OwnedFolder", "remove_abandoned"]
