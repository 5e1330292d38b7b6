"""Folders that a killed owner leaves behind are removed by the next owner; the one
folder that is meant to outlive its owners (matplotlib's) is private."""

from __future__ import annotations

import fcntl
import os
import stat
import time
from pathlib import Path

import pytest

from autograder.engine.slot import GradingSlot, matplotlib_folder
from autograder.sandbox.tempdirs import GRACE_SECONDS, LOCK_NAME, OwnedFolder, remove_abandoned

PREFIX = "autograder-test-"


def abandoned(parent: Path, name: str, *, age: float = 2 * GRACE_SECONDS) -> Path:
    """A folder as a killed owner leaves it: a lock file nobody holds, ``age`` seconds old."""
    folder = parent / f"{PREFIX}{name}"
    (folder / "work" / "submission-x").mkdir(parents=True)
    (folder / "work" / "submission-x" / "answer.txt").write_text("left")
    lock = folder / LOCK_NAME
    lock.write_text("")
    then = time.time() - age
    os.utime(lock, (then, then))
    return folder


def test_an_owned_folder_is_locked_while_it_lives_and_removed_after(tmp_path: Path) -> None:
    owned = OwnedFolder(prefix=PREFIX, parent=tmp_path)
    assert owned.path.parent == tmp_path and (owned.path / LOCK_NAME).is_file()
    fd = os.open(owned.path / LOCK_NAME, os.O_RDWR)
    try:
        with pytest.raises(BlockingIOError):  # another open file: the lock is held
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)
    owned.remove()
    owned.remove()  # twice is fine
    assert not owned.path.exists()


def test_the_next_owner_removes_what_a_dead_owner_left(tmp_path: Path) -> None:
    left = abandoned(tmp_path, "dead")
    owned = OwnedFolder(prefix=PREFIX, parent=tmp_path)
    assert not left.exists()
    assert owned.path.exists()
    owned.remove()


def test_live_young_foreign_and_unlocked_folders_stay(tmp_path: Path) -> None:
    live = OwnedFolder(prefix=PREFIX, parent=tmp_path)
    old = time.time() - 2 * GRACE_SECONDS
    os.utime(live.path / LOCK_NAME, (old, old))  # old, but its owner holds the lock
    young = abandoned(tmp_path, "young", age=1.0)  # its owner may not have locked it yet
    unmarked = tmp_path / f"{PREFIX}older-version"  # no lock file: not ours to judge
    unmarked.mkdir()
    other = tmp_path / "someone-else"  # another prefix
    other.mkdir()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    link = tmp_path / f"{PREFIX}link"  # a link to an abandoned folder is not followed
    link.symlink_to(abandoned(elsewhere, "target"))
    assert remove_abandoned(tmp_path, prefix=PREFIX) == []
    for folder in (live.path, young, unmarked, other, link, link.resolve()):
        assert folder.exists()
    live.remove()


def test_a_folder_of_another_user_stays(tmp_path: Path) -> None:
    if os.geteuid() != 0:
        pytest.skip("Not running as root: making another user's folder needs root.")
    left = abandoned(tmp_path, "foreign")
    for path in (left, left / LOCK_NAME):
        os.chown(path, 65534, 65534)
    assert remove_abandoned(tmp_path, prefix=PREFIX) == []
    assert left.exists()


def test_warm_parents_keep_one_private_matplotlib_folder() -> None:
    # Matplotlib builds its font list in MPLCONFIGDIR; a folder per slot would rebuild
    # it at every warm parent's start. One private folder per user outlives them.
    slot = GradingSlot(slot=0)
    try:
        slot.start()
        assert slot.warm_parent is not None
        environ = Path(f"/proc/{slot.warm_parent}/environ").read_bytes().split(b"\0")
        folder = matplotlib_folder()
        assert f"MPLCONFIGDIR={folder}".encode() in environ
        info = folder.stat()
        assert info.st_uid == os.geteuid() and stat.S_IMODE(info.st_mode) == 0o700
        assert stat.S_IMODE(folder.parent.stat().st_mode) == 0o700
        assert list(folder.glob("fontlist-*.json")), "matplotlib wrote no font list there"
    finally:
        slot.shutdown()
    assert folder.is_dir()
