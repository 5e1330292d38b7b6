"""The command line as a person uses it: release, check, clear errors, kill and resume."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from autograder.sandbox.tempdirs import GRACE_SECONDS, LOCK_NAME

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "assignments" / "hull" / "examples"

pytestmark = pytest.mark.slow


def autograder(*args: str, cwd: Path | None = None, timeout: float = 300,
               env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "autograder", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd, env=env)


@pytest.fixture(scope="module")
def released(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("release")
    proc = autograder("release", "hull", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "Wrote the student version" in proc.stdout
    return out


def test_student_checks_the_solution_before_submitting(released: Path) -> None:
    notebook = released / "hull.ipynb"
    shutil.copy(EXAMPLES / "solution.ipynb", notebook)
    proc = autograder("check", str(notebook), cwd=released)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PASS" in proc.stdout and "FAIL" not in proc.stdout
    assert "Hidden checks run when your notebook is graded" in proc.stdout
    # matplotlib draws with matplotlib.path ([rules] internal_use, released too): the
    # notebook's plotting cell is not called forbidden
    assert "raised" not in proc.stdout and "NotAllowedError" not in proc.stdout


def test_student_checks_a_wrong_answer(released: Path, tmp_path: Path) -> None:
    notebook = released / "mine.ipynb"
    shutil.copy(EXAMPLES / "wrong-clockwise.ipynb", notebook)
    proc = autograder("check", str(notebook), cwd=released)
    assert proc.returncode == 1
    assert "FAIL" in proc.stdout and "clockwise" in proc.stdout


@pytest.mark.parametrize(("args", "message"), [
    (["grade", "no-such-assignment", "x.ipynb", "--out", "o"], "no-such-assignment"),
    (["grade", "hull", "missing.ipynb", "--out", "o"], "does not exist"),
    (["grade", "hull", ".", "--out", "o", "--jobs", "0"], "must be at least 1"),
    (["grade", "hull", ".", "--out", "o", "--timeout", "soon"], "expected a number of seconds"),
    (["release", "hull"], "--out"),
])
def test_bad_arguments_get_a_message_not_a_traceback(tmp_path: Path, args: list[str], message: str) -> None:
    proc = autograder(*args, cwd=tmp_path)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_killed_batch_resumes_and_loses_nothing(tmp_path: Path) -> None:
    submissions = tmp_path / "submissions"
    submissions.mkdir()
    for k in range(12):
        shutil.copy(EXAMPLES / "wrong-clockwise.ipynb", submissions / f"student{k:02d}.ipynb")
    out = tmp_path / "out"
    scratch = tmp_path / "tmp"  # the runs' temporary folder, watched for leftovers
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}
    proc = subprocess.Popen([sys.executable, "-m", "autograder", "grade", "hull", str(submissions),
                             "--out", str(out), "--jobs", "1", "--no-progress"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True, env=env)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(out.glob("*/results.json"))) < 2:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    first = {p.parent.name for p in out.glob("*/results.json")}
    assert 2 <= len(first) < 12
    for path in out.glob("*/results.json"):
        json.loads(path.read_text())  # every file present is whole
    # A killed grader cleans nothing up: its slot folder (with the working directory
    # of the submission it was grading) stays, until the next grader finds it unlocked.
    killed = sorted(scratch.glob("autograder-slot-*"))
    assert killed, "the killed run left no slot folder: this test no longer tests its clean-up"
    # Everything else it had made in the temporary folder (the submission being
    # unpacked) was inside its slot folder, which the next grader removes.
    strays = sorted(p.name for p in scratch.iterdir() if not p.name.startswith("autograder-slot"))
    assert strays == [], f"the killed grader left {strays} that no later grader removes"
    past_grace = time.time() - 2 * GRACE_SECONDS  # as if the kill were long ago
    for folder in killed:
        os.utime(folder / LOCK_NAME, (past_grace, past_grace))
    again = autograder("grade", "hull", str(submissions), "--out", str(out), "--jobs", "2",
                       "--no-progress", env=env)
    assert again.returncode == 0, again.stderr
    assert f"reused {len(first)}" in again.stdout
    rows = (out / "grades.csv").read_text().splitlines()
    assert len(rows) == 13
    assert [p for p in killed if p.exists()] == []
    assert sorted(p.name for p in scratch.iterdir() if p.name.startswith("autograder-slot-")) == []
