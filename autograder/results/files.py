"""Files written atomically: a reader sees the old file or the new one, never half of either.

Each file is written beside its target, flushed to disk and renamed over it.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old or the new file, never half."""
    atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_bytes(path: Path, data: bytes, *, mode: int = 0o666) -> None:
    """Write ``data`` to ``path`` atomically; the file's mode follows the user's umask.

    The temporary file is created with ``os.open(..., 0o666)`` rather than
    :func:`tempfile.mkstemp` (always 0600), so the kernel applies the umask as
    for any other file the user writes, and a class folder stays readable by
    the course's group when the umask says so. ``mode=0o600`` makes a private
    file (access tokens), never readable by others, even for a moment.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{secrets.token_hex(6)}.tmp"
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), mode)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
