"""End to end: grade every problem notebook with the real CLI, and check nothing escaped.

The notebooks live in ``tests/files/problems/`` (written by
``tests/files/make_problems.py``), each with the outcome it must get in
``expected.toml``. One batch grades them all, in a subprocess, as a person would.
"""

from __future__ import annotations

import json
import os
import re
import socket
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import nbformat
import pytest

from autograder.sandbox import probe_support

ROOT = Path(__file__).resolve().parents[2]
PROBLEMS = ROOT / "tests" / "files" / "problems"
EXPECTED = tomllib.loads((PROBLEMS / "expected.toml").read_text())
HULL = ROOT / "assignments" / "hull"
SECRET = "s3cr3t-token-that-must-not-leak"
ESCAPE_FILES = [Path("/tmp/autograder-escaped"), Path.home() / "autograder-escaped",
                Path("/work/autograder-escaped"), Path("/autograder-escaped"),
                Path("/tmp/results.json")]
PORTS = range(47000, 47020)

pytestmark = pytest.mark.slow


class Listeners:
    """TCP listeners on loopback that record any connection a submission makes."""

    def __init__(self) -> None:
        self.sockets: list[socket.socket] = []
        self.accepted: list[int] = []
        for port in PORTS:
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                sock.close()
                continue
            sock.listen()
            sock.settimeout(0.2)
            self.sockets.append(sock)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._accept, daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        while not self._stop.is_set():
            for sock in self.sockets:
                try:
                    conn, _ = sock.accept()
                except OSError:
                    continue
                self.accepted.append(sock.getsockname()[1])
                conn.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        for sock in self.sockets:
            sock.close()


def huge_outputs_notebook(folder: Path) -> Path:
    """A correct submission carrying ~50 MB of outputs (made here, not committed)."""
    book = nbformat.read(PROBLEMS / "solution.ipynb", as_version=4)
    blob = "x" * (1024 * 1024)
    cell = book.cells[-1]
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=blob) for _ in range(50)]
    path = folder / "huge-outputs.ipynb"
    nbformat.write(book, path)
    return path


@pytest.fixture(scope="module")
def batch(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    for path in ESCAPE_FILES:
        path.unlink(missing_ok=True)
    extra = tmp_path_factory.mktemp("extra")
    huge = huge_outputs_notebook(extra)
    out = tmp_path_factory.mktemp("results")
    listeners = Listeners()
    env = dict(os.environ, SECRET_TOKEN=SECRET)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "autograder", "grade", str(HULL), str(PROBLEMS), str(huge),
             "--out", str(out), "--jobs", "2", "--timeout", "8", "--call-timeout", "4",
             "--no-progress"],
            capture_output=True, text=True, env=env, timeout=900, cwd=extra)
    finally:
        listeners.close()
    return {"out": out, "proc": proc, "accepted": listeners.accepted}


def load(batch: dict[str, object], name: str) -> dict[str, object]:
    out = batch["out"]
    assert isinstance(out, Path)
    path = out / name / "results.json"
    assert path.exists(), f"no results.json for {name}; grader said:\n{batch['proc']}"
    return json.loads(path.read_text())


def all_text(result: dict[str, object]) -> str:
    return json.dumps(result)


def test_batch_finishes_with_status_zero(batch: dict[str, object]) -> None:
    proc = batch["proc"]
    assert isinstance(proc, subprocess.CompletedProcess)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "Graded" in proc.stdout


def test_every_submission_has_a_row(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    rows = (out / "grades.csv").read_text().splitlines()
    ids = {row.split(",")[0] for row in rows[1:]}
    assert ids == set(EXPECTED) | {"huge-outputs"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_problem_notebook_gets_its_outcome(batch: dict[str, object], name: str) -> None:
    expected = EXPECTED[name]
    result = load(batch, name)
    fraction = result["score"] / result["max_score"] if result["max_score"] else 0.0
    band = {"0": (0.0, 0.0), "1": (1.0, 1.0), "partial": (0.01, 0.99)}[expected["score"]]
    assert band[0] - 1e-9 <= fraction <= band[1] + 1e-9, (
        f"{name}: score {result['score']}/{result['max_score']}; output: {result['output']}\n"
        + "\n".join(f"{t['name']}: {t['output'][:300]}" for t in result["tests"] if t["status"] != "passed"))
    if "outcome" in expected:
        assert result["extra_data"]["outcome"] == expected["outcome"], result["output"]
    for text in expected.get("contains", []):
        assert text in all_text(result), f"{name}: feedback lacks {text!r}"
    if "cell_errors" in expected:
        assert len(result["extra_data"]["cell_errors"]) == expected["cell_errors"]
    if "max_stdout" in expected:
        assert len(result["extra_data"]["stdout"]) <= expected["max_stdout"]


def test_huge_outputs_notebook_is_graded(batch: dict[str, object]) -> None:
    result = load(batch, "huge-outputs")
    assert result["score"] == result["max_score"] > 0


def test_no_file_escaped(batch: dict[str, object]) -> None:
    leaked = [str(p) for p in ESCAPE_FILES if p.exists()]
    out = batch["out"]
    assert isinstance(out, Path)
    forged = [p for p in out.rglob("results.json") if '"score": 100' in p.read_text()]
    assert not leaked and not forged


def test_no_connection_reached_a_listener(batch: dict[str, object]) -> None:
    assert batch["accepted"] == []


def test_hidden_checks_never_appear_in_results(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    # Lines of code, not data: a failing check may rightly quote the input it used.
    hidden_lines = [line.strip() for f in (HULL / "checks" / "hidden").glob("*.py")
                    for line in f.read_text().splitlines()
                    if len(line.strip()) > 30 and re.search(r"[A-Za-z_]{4,}", line)]
    assert hidden_lines, "the hull assignment should have hidden checks"
    for path in out.rglob("results.json"):
        text = path.read_text()
        found = [line for line in hidden_lines if line in text]
        assert not found, f"{path.parent.name} leaked hidden check text: {found[:2]}"


def test_no_secret_in_results(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    for path in out.rglob("results.json"):
        assert SECRET not in path.read_text(), path


def test_no_student_process_survives(batch: dict[str, object]) -> None:
    if not probe_support().is_root:
        pytest.skip("runs as a dedicated unprivileged user only when the grader is root")
    out = batch["out"]
    assert isinstance(out, Path)
    uids = set()  # the users this batch's workers ran as, from the notes of each result
    for path in out.rglob("results.json"):
        for note in json.loads(path.read_text())["extra_data"]["notes"]:
            found = re.search(r"uid and gid (\d+)", note)
            if found:
                uids.add(int(found.group(1)))
    assert uids, "the workers should have run as dedicated users"
    survivors = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                status = (entry / "status").read_text()
            except OSError:
                continue
            uid = next(int(line.split()[1]) for line in status.splitlines() if line.startswith("Uid:"))
            if uid in uids:
                survivors.append(entry.name)
    assert survivors == []


def test_regrading_reuses_every_result(batch: dict[str, object]) -> None:
    out = batch["out"]
    assert isinstance(out, Path)
    before = {p: p.read_text() for p in out.rglob("results.json")}
    proc = subprocess.run(
        [sys.executable, "-m", "autograder", "grade", str(HULL), str(PROBLEMS),
         "--out", str(out), "--jobs", "2", "--timeout", "8", "--call-timeout", "4", "--no-progress"],
        capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert f"reused {len(EXPECTED)}" in proc.stdout
    assert all(p.read_text() == text for p, text in before.items() if p.parent.name in EXPECTED)
