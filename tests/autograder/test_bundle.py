"""The assignment bundle that travels to Dask workers: unpacked as sent, and nothing else."""

from __future__ import annotations

import hashlib
import io
import tarfile
from pathlib import Path

import pytest

from autograder.engine.assignment import load_assignment
from autograder.errors import AssignmentError
from autograder.runners.bundle import Bundle, make_bundle


def test_a_bundle_unpacks_to_the_same_files(tmp_path: Path) -> None:
    hull = load_assignment("hull")
    bundle = make_bundle(hull)
    unpacked = bundle.unpack(tmp_path / "in")
    assert unpacked.name == "hull"
    sent = {p.relative_to(hull.root): p.read_bytes() for p in hull.root.rglob("*")
            if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"}
    got = {p.relative_to(unpacked.root): p.read_bytes() for p in unpacked.root.rglob("*")
           if p.is_file()}
    assert got == sent
    assert make_bundle(hull).data == bundle.data  # the same folder gives the same bytes


def _bundle_with(member: tarfile.TarInfo, data: bytes = b"") -> Bundle:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        archive.addfile(member, io.BytesIO(data) if member.isfile() else None)
    raw = buffer.getvalue()
    return Bundle(name="hull", data=raw, digest=hashlib.sha256(raw).hexdigest())


@pytest.mark.parametrize("kind", ["link", "parent", "absolute"])
def test_anything_but_a_plain_file_inside_is_refused(tmp_path: Path, kind: str) -> None:
    if kind == "link":
        member = tarfile.TarInfo("hull/checks/evil")
        member.type, member.linkname = tarfile.SYMTYPE, "/etc/passwd"
    else:
        member = tarfile.TarInfo("hull/../../escaped" if kind == "parent" else "/tmp/escaped")
        member.size = 1
    with pytest.raises(AssignmentError, match="not a plain file inside it"):
        _bundle_with(member, b"x").unpack(tmp_path / "in")
    assert not (tmp_path / "escaped").exists()
    assert [p.name for p in (tmp_path / "in").rglob("*") if p.is_file()] == []


def test_a_damaged_bundle_is_refused(tmp_path: Path) -> None:
    bundle = make_bundle(load_assignment("hull"))
    with pytest.raises(AssignmentError, match="damaged"):
        Bundle(name=bundle.name, data=bundle.data[:-1], digest=bundle.digest).unpack(tmp_path)
