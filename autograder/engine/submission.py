"""What one submission is: a notebook, a folder or a zip -> the files to grade.

A student hands in a notebook, a folder (nbgrader's
``submitted/<student>/<assignment>/``) or a zip (what otter and Gradescope hand
out). :func:`open_submission` turns any of them into a :class:`Submission`: for
each notebook the assignment expects (``Assignment.notebooks``, by file name),
the student's file; the other files; notes for the instructor (a stray copy, a
renamed notebook); or the problem that makes it ungradable.

Zips are unpacked with :mod:`zipfile` into a private scratch folder, member by
member, checking what :mod:`zipfile` leaves to the caller (its documentation
warns that ``extractall`` trusts the archive): the number of members, the bytes
actually written (never the sizes the archive declares), the compression ratio,
and names and types (no absolute paths, no ``..``, no links, no devices).
"""

from __future__ import annotations

import hashlib
import io
import os
import stat
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Sequence

from autograder.results.model import SUBMISSION_NOTE

#: folders of a submission that never hold what a student meant to hand in
IGNORED_FOLDERS = frozenset({".ipynb_checkpoints", "__MACOSX", "__pycache__", ".git"})


@dataclass(frozen=True)
class ZipLimits:
    """What a submitted zip may hold; a zip beyond any limit is ungradable, never unpacked."""

    max_members: int = 1000
    #: bytes of all members, counted as they are written
    max_total_bytes: int = 256 * 1024 * 1024
    #: uncompressed / compressed, for members larger than ``ratio_floor`` bytes
    max_ratio: float = 200.0
    ratio_floor: int = 1024 * 1024


@dataclass(frozen=True)
class Submission:
    """The files of one submission.

    Attributes
    ----------
    source : Path
        What was handed in (a notebook, a folder or a zip).
    notebooks : tuple of (str, Path)
        For each notebook the assignment expects (its file name), the student's file.
    extras : tuple of Path
        Every other file handed in (data, a stray copy), for the record.
    notes : tuple of str
        What a person should know (start with :data:`SUBMISSION_NOTE`).
    problem : str
        Why this cannot be graded at all ("" when it can).
    """

    source: Path
    notebooks: tuple[tuple[str, Path], ...] = ()
    extras: tuple[Path, ...] = ()
    notes: tuple[str, ...] = ()
    problem: str = ""

    @property
    def notebook(self) -> Path:
        """The first expected notebook's file (the submission itself when nothing was found)."""
        return self.notebooks[0][1] if self.notebooks else self.source


def is_zip(path: Path) -> bool:
    """True for a submission handed in as a zip (by its name, as the platforms name them)."""
    return path.suffix.lower() == ".zip"


def open_submission(path: Path, expected: Sequence[Path | str], *, scratch: Path,
                    limits: ZipLimits = ZipLimits()) -> Submission:
    """The files of the submission ``path``; a zip is unpacked below ``scratch``.

    ``expected``: the notebooks the assignment expects (paths or file names),
    the main one first. A plain file is returned as the main notebook whatever its
    name (the engine's reader says what is wrong with it, if anything).
    """
    names = [Path(p).name for p in expected]
    path = Path(path)
    if path.is_symlink() or not (path.is_dir() or is_zip(path)):
        return Submission(source=path, notebooks=((names[0], path),))
    if path.is_dir():
        return _from_folder(path, path, names, what="folder")
    folder, problem = unpack_zip(path, scratch, limits)
    if problem:
        return Submission(source=path, problem=problem)
    return _from_folder(path, folder, names, what="zip")


def _from_folder(source: Path, folder: Path, names: Sequence[str], *, what: str) -> Submission:
    files = _files_below(folder)
    notebooks = [f for f in files if f.suffix == ".ipynb"]
    if not notebooks:
        listed = ", ".join(names)
        return Submission(source=source, extras=tuple(files), problem=(
            f"No notebook (.ipynb) was found in this {what}; the assignment expects {listed}. "
            "Hand in the notebook itself, or a zip with the notebook inside."))
    chosen: list[tuple[str, Path]] = []
    notes: list[str] = []
    for name in names:
        named = [f for f in notebooks if f.name == name]
        if named:  # the shallowest copy: a nested one is a stray copy
            chosen.append((name, min(named, key=lambda f: (len(f.parts), str(f)))))
    if not chosen and len(names) == 1:
        pick = notebooks[0]
        chosen.append((names[0], pick))
        if len(notebooks) == 1:
            notes.append(f"{SUBMISSION_NOTE}the notebook is named {_rel(pick, folder)!r}, not "
                         f"{names[0]!r}; it was graded as {names[0]!r}.")
    missing = [n for n in names if n not in dict(chosen)]
    if missing and chosen:
        notes.append(f"{SUBMISSION_NOTE}{', '.join(map(repr, missing))} "
                     f"{'is' if len(missing) == 1 else 'are'} missing from this {what}.")
    if not chosen:
        return Submission(source=source, extras=tuple(files), problem=(
            f"None of the {len(notebooks)} notebooks in this {what} "
            f"({', '.join(_rel(f, folder) for f in notebooks[:5])}) is {', '.join(names)}; "
            "hand in the assignment's notebook under its released name."))
    used = {p for _, p in chosen}
    others = [f for f in notebooks if f not in used]
    if others:
        graded = ", ".join(_rel(p, folder) for _, p in chosen)
        notes.append(f"{SUBMISSION_NOTE}{len(others)} more notebook(s) than expected in this "
                     f"{what} ({', '.join(_rel(f, folder) for f in others[:5])}); graded "
                     f"{graded}. Check that it is the one the student meant.")
    return Submission(source=source, notebooks=tuple(chosen),
                      extras=tuple(f for f in files if f not in used), notes=tuple(notes))


def _files_below(folder: Path) -> list[Path]:
    """Regular files and links under ``folder``, sorted, without the ignored folders."""
    found = []
    for directory, subdirs, files in os.walk(folder, followlinks=False):
        subdirs[:] = sorted(d for d in subdirs if d not in IGNORED_FOLDERS)
        found += [Path(directory, name) for name in sorted(files)]
    return found


def _rel(path: Path, folder: Path) -> str:
    return str(path.relative_to(folder))


# -- zips ---------------------------------------------------------------------

class _Refused(Exception):
    """A zip member or the whole zip is refused; the message says why."""


def unpack_zip(path: Path, scratch: Path, limits: ZipLimits = ZipLimits()) -> tuple[Path, str]:
    """Unpack ``path`` into a new private folder under ``scratch``: (folder, problem).

    ``problem`` is "" when the zip was unpacked, else the student's message (and the
    folder may hold part of it: the caller's scratch folder is removed with it).
    """
    target = scratch / "unpacked"
    target.mkdir(mode=0o700)
    try:
        mode = os.lstat(path).st_mode
        if not stat.S_ISREG(mode):
            raise _Refused("this zip is not a regular file")
        with zipfile.ZipFile(path) as archive:
            members = archive.infolist()
            if len(members) > limits.max_members:
                raise _Refused(f"it holds {len(members)} files; at most {limits.max_members} "
                               "are accepted")
            declared = sum(i.file_size for i in members)
            if declared > limits.max_total_bytes:
                raise _Refused(f"it unpacks to {declared / 1e6:.1f} MB; at most "
                               f"{limits.max_total_bytes / 1e6:.1f} MB are accepted")
            for info in members:  # what the zip declares, before writing anything
                _check_ratio(info, info.file_size, limits)
            written = 0  # and what it really holds, as it is written (headers can lie)
            for info in members:
                written += _extract(archive, info, target, limits, limits.max_total_bytes - written)
    except _Refused as exc:
        return target, (f"This zip could not be unpacked safely: {exc}. Zip only the notebook "
                        "and the files it needs (no links, no folders outside the zip), or "
                        "hand in the notebook itself.")
    except (zipfile.BadZipFile, zipfile.LargeZipFile, NotImplementedError, EOFError,
            OSError, ValueError) as exc:
        return target, (f"This is not a zip the grader can read ({type(exc).__name__}: "
                        f"{str(exc)[:160]}). Zip the folder again, or hand in the notebook itself.")
    return target, ""


def _extract(archive: zipfile.ZipFile, info: zipfile.ZipInfo, target: Path,
             limits: ZipLimits, budget: int) -> int:
    """Write one member below ``target``; return its bytes. Raises :class:`_Refused`."""
    parts = _member_parts(info.filename)
    kind = stat.S_IFMT(info.external_attr >> 16)
    if kind == stat.S_IFLNK:
        raise _Refused(f"{info.filename!r} is a symbolic link")
    if kind not in (0, stat.S_IFREG, stat.S_IFDIR):
        raise _Refused(f"{info.filename!r} is a device, pipe or socket, not a file")
    if info.flag_bits & 0x1:
        raise _Refused(f"{info.filename!r} is encrypted")
    if not parts or parts[0] in IGNORED_FOLDERS:
        return 0
    if info.is_dir() or kind == stat.S_IFDIR:
        _make_dirs(target, parts)
        return 0
    folder = _make_dirs(target, parts[:-1])
    try:
        fd = os.open(folder / parts[-1], os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW,
                     0o600)
    except FileExistsError:
        raise _Refused(f"{info.filename!r} appears twice") from None
    written = 0
    with os.fdopen(fd, "wb") as out, archive.open(info) as member:
        while block := member.read(1 << 16):
            written += len(block)
            if written > budget:
                raise _Refused(f"it unpacks to more than {limits.max_total_bytes / 1e6:.1f} MB; "
                               "at most that is accepted")
            _check_ratio(info, written, limits)
            out.write(block)
    return written


def _check_ratio(info: zipfile.ZipInfo, size: int, limits: ZipLimits) -> None:
    if size > limits.ratio_floor and size > limits.max_ratio * max(info.compress_size, 1):
        raise _Refused(f"{info.filename!r} is compressed more than {limits.max_ratio:g} times "
                       "(a zip bomb?)")


def _member_parts(name: str) -> tuple[str, ...]:
    """The path parts of a member name; refuses absolute names, drives and ``..``."""
    text = name.replace("\\", "/")
    if text.startswith("/") or (len(text) > 1 and text[1] == ":"):
        raise _Refused(f"{name!r} is an absolute path")
    parts = tuple(p for p in PurePosixPath(text).parts if p not in ("", "."))
    if ".." in parts:
        raise _Refused(f"{name!r} points outside the zip (..)")
    if any("\0" in p for p in parts):
        raise _Refused(f"{name!r} is not a valid file name")
    return parts


def _make_dirs(target: Path, parts: Sequence[str]) -> Path:
    """``target/parts...`` as real folders (a member never turns a folder into a link)."""
    folder = target
    for part in parts:
        folder = folder / part
        try:
            os.mkdir(folder, 0o700)
        except FileExistsError:
            if not stat.S_ISDIR(os.lstat(folder).st_mode):
                raise _Refused(f"{part!r} is both a file and a folder in this zip") from None
    return folder


def submission_bytes(path: Path) -> tuple[bytes, str]:
    """What to send for ``path`` to a grader on another machine: (bytes, file name).

    A file as it is; a folder as a zip of its regular files (links and special files
    are left out: they would be refused in the folder too), which
    :func:`open_submission` unpacks there into the same files.
    """
    path = Path(path)
    if not path.is_dir() or path.is_symlink():
        return path.read_bytes(), path.name
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for file in _files_below(path):
            if stat.S_ISREG(os.lstat(file).st_mode):
                archive.write(file, file.relative_to(path).as_posix())
    return buffer.getvalue(), f"{path.name}.zip"


def submission_sha256(path: Path) -> str:
    """SHA-256 of what was handed in: a file's bytes, or a folder's names and bytes.

    A link inside a folder counts by its target's text, never followed.
    """
    path = Path(path)
    if not path.is_dir() or path.is_symlink():
        return file_sha256(path)
    digest = hashlib.sha256()
    for file in _files_below(path):
        digest.update(str(file.relative_to(path)).encode("utf-8", "surrogateescape") + b"\0")
        if file.is_symlink():
            digest.update(b"link:" + os.fsencode(os.readlink(file)))
        else:
            digest.update(file_sha256(file).encode())
    return digest.hexdigest()


def file_sha256(path: Path) -> str:
    """SHA-256 of a regular file; a link, pipe or device is never opened (it could block)."""
    digest = hashlib.sha256()
    try:
        mode = os.lstat(path).st_mode
        if not stat.S_ISREG(mode):
            return hashlib.sha256(f"special:{stat.S_IFMT(mode)}".encode()).hexdigest()
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
    except OSError as exc:
        digest.update(f"unreadable:{exc}".encode())
    return digest.hexdigest()


__all__ = ["IGNORED_FOLDERS", "Submission", "ZipLimits", "is_zip", "open_submission",
           "file_sha256", "submission_bytes", "submission_sha256", "unpack_zip"]
