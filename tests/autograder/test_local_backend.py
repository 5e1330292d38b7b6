"""The local pool (``--jobs N``): this process is one slot, the pool's processes the others.

Whatever happens to a slot process or to the command (a slot process killed, Ctrl-C
on the whole process group), every submission ends with one whole result or none,
and no process or folder of the run is left behind.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import psutil
import pytest

from autograder import api
from autograder.results.model import SubmissionResult
from autograder.runners import local
from tests.support.terminal import with_ctrl_c

ROOT = Path(__file__).resolve().parents[2]
SOLUTION = ROOT / "assignments" / "hull" / "examples" / "solution.ipynb"

pytestmark = pytest.mark.slow


def copies(folder: Path, count: int) -> Path:
    folder.mkdir(parents=True)
    for k in range(count):
        shutil.copy(SOLUTION, folder / f"student{k:02d}.ipynb")
    return folder


def slot_processes() -> list[psutil.Process]:
    """This process's pool processes (spawned by multiprocessing)."""
    return [p for p in psutil.Process().children()
            if "spawn_main" in " ".join(p.cmdline())]


def test_a_killed_slot_process_costs_no_submission(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    submissions = copies(tmp_path / "in", 12)
    # A killed process cannot remove its slot's folder: it goes here, not to /tmp.
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr(tempfile, "tempdir", None)
    killed: list[int] = []
    pool_reported = threading.Event()

    def kill_the_pool(result: SubmissionResult) -> None:
        # Once, at the first result a pool process graded (reported from the pool's
        # feeder thread): the pool is ready then, and whatever its other process held
        # is graded again, by a new pool or by this process's slot.
        if not killed and threading.current_thread() is not threading.main_thread():
            for proc in slot_processes():
                proc.kill()
                killed.append(proc.pid)
            pool_reported.set()

    # This process's slot starts grading only once the pool has graded one file, so
    # however fast this slot is, the pool gets files to lose.
    grade_here = local.grade_one

    def grade_after_the_pool(*args: Any, **kwargs: Any) -> SubmissionResult:
        pool_reported.wait(timeout=600)
        return grade_here(*args, **kwargs)

    monkeypatch.setattr(local, "grade_one", grade_after_the_pool)
    report = api.grade("hull", [submissions], out=tmp_path / "out", jobs=3, progress=False,
                       on_result=kill_the_pool)
    assert killed, "no pool process graded a file"
    assert sorted(r.id for r in report.results) == [f"student{k:02d}" for k in range(12)]
    assert {r.outcome for r in report.results} == {"graded"}
    assert all(r.score == r.max_score for r in report.results)
    stored = sorted(p.parent.name for p in (tmp_path / "out").glob("*/results.json"))
    assert stored == [r.id for r in report.results]


def test_a_pool_that_cannot_start_costs_no_submission(tmp_path: Path,
                                                    monkeypatch: pytest.MonkeyPatch,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # Seen once in CI: multiprocessing's resource tracker pipe was broken when the pool
    # was set up. This process's slot then grades every file, and says why.
    submissions = copies(tmp_path / "in", 3)

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(multiprocessing.get_context("spawn"), "Value", broken)
    report = api.grade("hull", [submissions], out=tmp_path / "out", jobs=2, progress=False)
    assert sorted(r.id for r in report.results) == ["student00", "student01", "student02"]
    assert all(r.outcome == "graded" and r.score == r.max_score for r in report.results)
    assert "could not start 1 more grading process(es) (BrokenPipeError" in capsys.readouterr().err


def test_ctrl_c_keeps_whole_results_and_leaves_nothing_behind(tmp_path: Path) -> None:
    submissions = copies(tmp_path / "in", 10)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    out = tmp_path / "out"
    grade = [sys.executable, "-m", "autograder", "grade", "hull", str(submissions),
             "--out", str(out), "--jobs", "2", "--no-progress"]
    proc = subprocess.Popen(with_ctrl_c(grade),  # even when this pytest ignores SIGINT
                            env={**os.environ, "TMPDIR": str(scratch)}, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while not list(out.glob("*/results.json")) and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 130, err[-3000:]
    assert "interrupted" in err
    for path in out.glob("*/results.json"):  # whatever was stored is whole
        result = json.loads(path.read_text())
        assert result["extra_data"]["outcome"] == "graded"
        assert result["score"] == result["max_score"]
    # The session's processes end with it (the warm parents on their parent's death).
    deadline = time.monotonic() + 60
    while _in_session(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert _in_session(proc.pid) == []
    left = sorted(p.name for p in scratch.iterdir()
                  if p.name.startswith(("submission-", "autograder-slot-")))
    assert left == []


def _in_session(sid: int) -> list[str]:
    found = []
    for proc in psutil.process_iter():
        try:
            if os.getsid(proc.pid) == sid and proc.status() != psutil.STATUS_ZOMBIE:
                found.append(" ".join(proc.cmdline())[:200])
        except (OSError, psutil.Error):
            continue
    return found
