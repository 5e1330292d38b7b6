"""The assignment as one content-hashed archive, for graders on other machines.

A remote grader needs the assignment folder (``assignment.toml``, the checks,
the data) but shares no file system with the instructor's machine. The folder
travels as one reproducible tar archive whose name is the SHA-256 of its bytes:
the same folder gives the same archive on every machine, so a worker can tell
that it grades with exactly the checks the client has.

The archive is unpacked into a fresh private directory (mode 0700, outside
every path the sandbox lets student code read) and loaded from there.
"""

from __future__ import annotations

import gzip
import hashlib
import io
import os
import shutil
import tarfile
import tempfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from autograder.engine.assignment import Assignment, load_assignment
from autograder.errors import AssignmentError

#: what never travels: caches and editor leftovers
_SKIPPED_DIRS = frozenset({"__pycache__", ".ipynb_checkpoints", ".pytest_cache", ".git"})
_SKIPPED_SUFFIXES = (".pyc", ".pyo")


@dataclass(frozen=True)
class Bundle:
    """An assignment folder packed as a reproducible ``tar.gz``."""

    name: str  # the folder's name, which is the assignment's root folder name when unpacked
    data: bytes
    digest: str  # SHA-256 of ``data``

    def unpack(self, into: Path) -> Assignment:
        """Unpack under ``into`` (created 0700) after checking the digest; load the assignment."""
        if hashlib.sha256(self.data).hexdigest() != self.digest:
            raise AssignmentError("The assignment bundle is damaged (its SHA-256 does not match "
                                  "its name); grade again to send it anew.")
        into.mkdir(mode=0o700, parents=True, exist_ok=True)
        os.chmod(into, 0o700)
        target = into / self.digest[:16]
        if not (target / self.name / "assignment.toml").exists():
            staging = Path(tempfile.mkdtemp(dir=into, prefix=".unpack-"))
            with tarfile.open(fileobj=io.BytesIO(self.data), mode="r:gz") as archive:
                _extract_files(archive, staging)
            staging.rename(target)
        return load_assignment(target / self.name)


def _extract_files(archive: tarfile.TarFile, into: Path) -> None:
    """Write the archive's regular files under ``into``; anything else is refused.

    By hand rather than ``extractall(filter="data")``: extraction filters exist only
    from Python 3.11.4, and Debian 12's 3.11.2 (which ``requires-python`` admits)
    has none. A bundle holds regular files only (:func:`make_bundle`), so this is
    the stricter rule as well: no links, devices, absolute or ``..`` paths.
    """
    for member in archive:
        parts = PurePosixPath(member.name).parts
        if not member.isfile() or not parts or parts[0] == "/" or ".." in parts:
            raise AssignmentError(f"The assignment bundle holds {member.name!r}, which is not "
                                  "a plain file inside it; grade again to send it anew.")
        source = archive.extractfile(member)
        assert source is not None  # a regular file always has data
        path = into.joinpath(*parts)
        path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
        path.write_bytes(source.read())


def _files(root: Path) -> list[Path]:
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d not in _SKIPPED_DIRS)
        for name in sorted(filenames):
            if not name.endswith(_SKIPPED_SUFFIXES):
                found.append(Path(dirpath) / name)
    return found


def make_bundle(assignment: Assignment) -> Bundle:
    """Pack ``assignment.root`` reproducibly: sorted entries, zero times and owners, fixed modes."""
    root = assignment.root.resolve()
    buffer = io.BytesIO()
    # gzip's header time is fixed too (mtime=0), so equal folders give equal bytes
    with gzip.GzipFile(fileobj=buffer, mode="wb", mtime=0, compresslevel=6) as packed, \
            tarfile.open(fileobj=packed, mode="w", format=tarfile.PAX_FORMAT) as archive:
        for path in _files(root):
            info = tarfile.TarInfo(f"{root.name}/{path.relative_to(root).as_posix()}")
            data = path.read_bytes()
            info.size, info.mtime, info.mode = len(data), 0, 0o644
            info.uid = info.gid = 0
            info.uname = info.gname = ""
            archive.addfile(info, io.BytesIO(data))
    data = buffer.getvalue()
    return Bundle(name=root.name, data=data, digest=hashlib.sha256(data).hexdigest())


def engine_fingerprint() -> str:
    """The engine version and the digest of the ``autograder`` and ``reference`` sources.

    A worker compares it with the client's before grading: a different engine or
    reference package could give different scores under the same result key. The
    same digest is part of every result key (``autograder.engine.grader.engine_digest``);
    it is computed afresh here, so a long-lived client upgraded on disk is compared
    as it now is. ``reference`` is located, never imported.
    """
    from autograder.engine.grader import ENGINE_VERSION, engine_digest

    fresh = engine_digest.__wrapped__()  # the uncached function behind functools.cache
    return hashlib.sha256(f"{ENGINE_VERSION}|{fresh}".encode()).hexdigest()


def private_directory(prefix: str = "autograder-bundle-", *, parent: Path | None = None) -> Path:
    """A fresh 0700 directory under ``parent`` (default: the system's temporary folder)."""
    return Path(tempfile.mkdtemp(prefix=prefix, dir=parent))


def remove_directory(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)


__all__ = ["Bundle", "engine_fingerprint", "make_bundle", "private_directory", "remove_directory"]
