"""Zip submissions (what otter and Gradescope hand out): graded like the notebook inside,
and hostile zips (bombs, links, traversal, devices) ungradable with a message, never unpacked
outside a private scratch folder."""

from __future__ import annotations

import json
import stat
import zipfile
from pathlib import Path

import pytest

from autograder.engine.submission import ZipLimits, open_submission, submission_sha256, unpack_zip

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
SOLUTION = HULL / "examples" / "solution.ipynb"


def _zip(path: Path, members: dict[str, bytes], *, modes: dict[str, int] | None = None,
         method: int = zipfile.ZIP_DEFLATED) -> Path:
    """``path``: a zip of ``members``; ``modes`` gives a member's Unix file type and mode."""
    with zipfile.ZipFile(path, "w", compression=method) as archive:
        for name, data in members.items():
            info = zipfile.ZipInfo(name)
            info.compress_type = method
            if modes and name in modes:
                info.external_attr = modes[name] << 16
            archive.writestr(info, data)
    return path


def _hostile(folder: Path) -> dict[str, Path]:
    """Named hostile zips, each with the words its refusal must say."""
    notebook = SOLUTION.read_bytes()
    folder.mkdir(parents=True, exist_ok=True)
    return {
        "compressed more than": _zip(folder / "bomb.zip", {"hull.ipynb": notebook,
                                                            "zeros.bin": bytes(40 * 2**20)}),
        "symbolic link": _zip(folder / "link.zip", {"hull.ipynb": b"/etc/passwd"},
                              modes={"hull.ipynb": stat.S_IFLNK | 0o777}),
        "outside the zip": _zip(folder / "traversal.zip", {"../../escaped.ipynb": notebook,
                                                            "hull.ipynb": notebook}),
        "absolute path": _zip(folder / "absolute.zip", {"/tmp/numgrade-absolute.ipynb": notebook}),
        "device": _zip(folder / "device.zip", {"hull.ipynb": b""},
                       modes={"hull.ipynb": stat.S_IFCHR | 0o666}),
        "not a zip": _write(folder / "broken.zip", b"PK\x03\x04 not really a zip"),
    }


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("words", ["compressed more than", "symbolic link", "outside the zip",
                                   "absolute path", "device", "not a zip"])
def test_hostile_zips_are_refused_with_a_message(tmp_path: Path, words: str) -> None:
    archive = _hostile(tmp_path / "zips")[words]
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    submission = open_submission(archive, [HULL / "hull.ipynb"], scratch=scratch)
    assert words in submission.problem and not submission.notebooks
    assert "zip" in submission.problem.lower()
    # nothing was written outside the private folder, and no link was made inside it
    assert not (tmp_path / "escaped.ipynb").exists() and not (tmp_path.parent / "escaped.ipynb").exists()
    assert not Path("/tmp/numgrade-absolute.ipynb").exists()
    assert not any(p.is_symlink() for p in scratch.rglob("*"))
    written = sum(p.stat().st_size for p in scratch.rglob("*") if p.is_file())
    assert written <= 2 * 2**20  # the bomb stopped within its ratio floor, not at 40 MiB


def test_zip_limits_count_members_and_written_bytes(tmp_path: Path) -> None:
    many = _zip(tmp_path / "many.zip", {f"f{k}.txt": b"x" for k in range(30)})
    (tmp_path / "a").mkdir()
    _, problem = unpack_zip(many, tmp_path / "a", ZipLimits(max_members=20))
    assert "30 files" in problem
    big = _zip(tmp_path / "big.zip", {"hull.ipynb": SOLUTION.read_bytes(), "data.bin": bytes(3000)},
               method=zipfile.ZIP_STORED)
    (tmp_path / "b").mkdir()
    _, problem = unpack_zip(big, tmp_path / "b", ZipLimits(max_total_bytes=2000))
    assert "unpacks to" in problem and "at most 0.0 MB" in problem


def test_a_zip_holds_the_notebook_its_folder_and_a_stray_copy(tmp_path: Path) -> None:
    notebook = SOLUTION.read_bytes()
    archive = _zip(tmp_path / "alice.zip", {
        "alice/hull.ipynb": notebook, "alice/old/hull.ipynb": b"{}",
        "alice/.ipynb_checkpoints/hull-checkpoint.ipynb": b"{}", "__MACOSX/._hull.ipynb": b"x",
        "alice/notes.txt": b"hi"})
    (tmp_path / "s").mkdir()
    submission = open_submission(archive, [HULL / "hull.ipynb"], scratch=tmp_path / "s")
    assert submission.problem == ""
    assert submission.notebook.read_bytes() == notebook  # the shallowest hull.ipynb
    assert [p.name for p in submission.extras] == ["notes.txt", "hull.ipynb"]
    assert len(submission.notes) == 1 and "old/hull.ipynb" in submission.notes[0]
    assert "checkpoint" not in " ".join(submission.notes)
    empty = _zip(tmp_path / "empty.zip", {"readme.txt": b"forgot it"})
    (tmp_path / "e").mkdir()
    assert "No notebook" in open_submission(empty, [HULL / "hull.ipynb"], scratch=tmp_path / "e").problem


def test_a_folder_is_hashed_by_names_and_bytes(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "hull.ipynb").write_text("1")
    first = submission_sha256(tmp_path / "a")
    (tmp_path / "a" / "hull.ipynb").write_text("2")
    assert submission_sha256(tmp_path / "a") != first  # an edit regrades the folder


@pytest.mark.slow
def test_zips_are_graded_and_hostile_ones_get_a_result(tmp_path: Path) -> None:
    from autograder import api
    from autograder.engine.grader import GradingOptions

    subs = tmp_path / "subs"
    subs.mkdir()
    _zip(subs / "alice.zip", {"hull.ipynb": SOLUTION.read_bytes()})
    (subs / "bob.ipynb").write_bytes(SOLUTION.read_bytes())
    for words, archive in _hostile(tmp_path / "zips").items():
        archive.rename(subs / archive.name)
    report = api.grade("hull", [subs], out=tmp_path / "out", jobs=1, progress=False,
                       options=GradingOptions(public_only=True))
    by_id = {r.id: r for r in report.results}
    assert set(by_id) == {"alice", "bob", "bomb", "link", "traversal", "absolute", "device", "broken"}
    assert by_id["alice"].outcome == "graded"
    assert by_id["alice"].score == by_id["bob"].score == by_id["alice"].max_score > 0
    for name in ("bomb", "link", "traversal", "absolute", "device", "broken"):
        assert by_id[name].outcome == "ungradable", name
        assert "zip" in by_id[name].output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    flagged = {a["id"] for a in summary["attention"]}
    assert flagged == {"bomb", "link", "traversal", "absolute", "device", "broken"}


def test_a_folder_sent_to_another_machine_arrives_as_the_same_files(tmp_path: Path) -> None:
    """A Dask node gets bytes: a folder goes as a zip and is unpacked into the same choice."""
    from autograder.engine.submission import submission_bytes

    folder = tmp_path / "alice" / "hull"
    (folder / ".ipynb_checkpoints").mkdir(parents=True)
    (folder / "hull.ipynb").write_bytes(SOLUTION.read_bytes())
    (folder / "hull-Copy1.ipynb").write_text("{}")
    (folder / ".ipynb_checkpoints" / "hull-checkpoint.ipynb").write_text("{}")
    (folder / "passwd.ipynb").symlink_to("/etc/passwd")
    data, name = submission_bytes(folder)
    assert name == "hull.zip"
    sent = tmp_path / "node" / name
    sent.parent.mkdir()
    sent.write_bytes(data)
    (tmp_path / "s1").mkdir()
    (tmp_path / "s2").mkdir()
    here = open_submission(folder, [HULL / "hull.ipynb"], scratch=tmp_path / "s1")
    there = open_submission(sent, [HULL / "hull.ipynb"], scratch=tmp_path / "s2")
    assert there.notebook.read_bytes() == here.notebook.read_bytes() == SOLUTION.read_bytes()
    assert [p.name for p in there.extras] == ["hull-Copy1.ipynb"]
    assert len(there.notes) == 1 and "hull-Copy1.ipynb" in there.notes[0]
