"""The service against a submission that attacks the channel: the queue keeps moving.

One grading process, an attacking upload (it floods the channel and never reads,
see ``tests/autograder/test_channel.py``) and then an honest one: the honest upload
must be graded (a generous timeout fails the test instead of waiting forever) and
the attacker must get the student's outcome, never ``error``. The lease keeper is
tested on its own too: past the grading's deadline it stops renewing and ends the
stuck grading process.
"""

from __future__ import annotations

import datetime as dt
import shutil
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import nbformat
import pytest
import svc_support as support
from conftest import iso

from autograder.service import graders, jobqueue
from autograder.service.settings import GraderSettings
from tests.autograder.test_channel import FLOOD
from tests.files.make_problems import SOLUTION, nb

#: seconds within which both uploads must be graded (each takes well under a minute)
GRADED_WITHIN = 900.0


def channel_course(folder: Path) -> Path:
    now = dt.datetime.now(dt.timezone.utc)
    body = f"""
[course]
name = "Channel"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "hull"
opens = 2020-01-01T00:00:00Z
deadline = {iso(now + dt.timedelta(days=30))}
"""
    roster = [("mallory", "Mallory", "m@example.edu", "student"),
              ("honest", "Hon Est", "h@example.edu", "student")]
    return support.write_course(folder, body=body, roster=roster)


@pytest.fixture
def own_tmpdir(monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """``TMPDIR`` of the service this test starts (world-traversable, as /tmp is)."""
    folder = Path(tempfile.mkdtemp(prefix="numgrade-channel-service-"))
    folder.chmod(0o755)
    monkeypatch.setenv("TMPDIR", str(folder))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


@pytest.mark.slow
def test_honest_upload_is_graded_after_an_attacking_one(tmp_path: Path, own_tmpdir: Path) -> None:
    course = channel_course(tmp_path / "course")
    server = support.Server(course, f"sqlite:///{tmp_path / 'course.sqlite3'}", jobs=1).start()
    try:
        tokens = server.tokens()
        with httpx.Client(timeout=120) as client:
            attack = support.upload(client, server.url, tokens["mallory"], "hull",
                                    nbformat.writes(nb(SOLUTION, FLOOD)).encode())
            honest = support.upload(client, server.url, tokens["honest"], "hull",
                                    nbformat.writes(nb(SOLUTION)).encode())
            assert attack.status_code == 201 and honest.status_code == 201, attack.text
            good = support.wait_graded(client, server.url, tokens["honest"], honest.json()["id"],
                                       timeout=GRADED_WITHIN)
            bad = support.wait_graded(client, server.url, tokens["mallory"], attack.json()["id"],
                                      timeout=GRADED_WITHIN)
        assert good["status"] == "graded", good
        assert good["score"] == good["max_score"] > 0
        assert bad["status"] == "graded" and bad["outcome"] != "error", bad
        assert bad["score"] < bad["max_score"]
    finally:
        server.stop()


class _Renewals:
    """Stands in for :func:`jobqueue.renew`: counts renewals, sets ``stop`` after ``until``."""

    def __init__(self, stop: threading.Event, until: int) -> None:
        self.count, self._stop, self._until = 0, stop, until

    def __call__(self, factory: Any, job: jobqueue.Claimed, *, lease_seconds: float) -> bool:
        self.count += 1
        if self.count >= self._until:
            self._stop.set()
        return True


JOB = jobqueue.Claimed(job_id=1, submission_id=1, kind="grade", claim="c", tries=1)
SETTINGS = GraderSettings(course_path="", database_url="", lease_seconds=0.03)


def test_lease_is_renewed_while_the_grading_is_within_its_deadline(
        monkeypatch: pytest.MonkeyPatch) -> None:
    stop, overruns = threading.Event(), []
    renewals = _Renewals(stop, until=3)
    monkeypatch.setattr(jobqueue, "renew", renewals)
    graders._keep_lease(None, JOB, SETTINGS, stop, deadline=time.monotonic() + 3600,
                        overrun=lambda: overruns.append(1))
    assert renewals.count == 3 and overruns == []


def test_lease_is_not_renewed_past_the_deadline_and_the_process_is_replaced(
        monkeypatch: pytest.MonkeyPatch) -> None:
    stop, overruns = threading.Event(), []
    renewals = _Renewals(stop, until=1_000_000)
    monkeypatch.setattr(jobqueue, "renew", renewals)
    graders._keep_lease(None, JOB, SETTINGS, stop, deadline=time.monotonic() - 1,
                        overrun=lambda: overruns.append(1))
    assert renewals.count == 0 and overruns == [1]


def test_the_grading_deadline_covers_the_submissions_whole_budget() -> None:
    from autograder.engine.assignment import load_assignment
    from autograder.engine.grader import Grader

    with Grader(load_assignment(support.ROOT / "assignments" / "hull")) as grader:
        limit = grader.wall_limit()
        held = graders._Graders.__new__(graders._Graders)
        held.get = lambda name: grader  # type: ignore[method-assign]
        submission = type("S", (), {"assignment": "hull"})()
        deadline = graders.grading_deadline(held, submission)  # type: ignore[arg-type]
    # hull: notebook 60 s, calls 10 s: a CPU budget of 260 s, backstops 4x + 15 s
    assert limit >= 2 * (4 * 260 + 15) + 4 * (4 * 60 + 15)
    assert deadline is not None and deadline - time.monotonic() >= limit


def test_the_dispatcher_does_not_renew_an_overdue_lease(monkeypatch: pytest.MonkeyPatch) -> None:
    from autograder.service import dispatch

    stop = threading.Event()
    renewed: list[int] = []

    def renew(factory: Any, job: jobqueue.Claimed, *, lease_seconds: float) -> bool:
        renewed.append(job.job_id)
        if len(renewed) >= 6:
            stop.set()
        return True

    monkeypatch.setattr(jobqueue, "renew", renew)
    leases = dispatch._Leases(None, lease_seconds=0.03)  # type: ignore[arg-type]
    leases._stop = stop
    leases.hold(JOB, deadline=time.monotonic() + 3600)
    leases.hold(jobqueue.Claimed(job_id=2, submission_id=2, kind="grade", claim="d", tries=1),
                deadline=time.monotonic() - 1)
    leases._run()
    assert renewed and set(renewed) == {1}


def test_the_dispatcher_gives_an_overdue_grading_an_error_result() -> None:
    from autograder.service import dispatch

    recorded: list[tuple[Any, Any]] = []
    cancelled: list[str] = []

    class Future:
        def __init__(self, name: str) -> None:
            self.name = name

        def cancel(self) -> None:
            cancelled.append(self.name)

    late = dispatch._Flight(JOB, None, Path("late.ipynb"), deadline=time.monotonic() - 1)  # type: ignore[arg-type]
    fresh = dispatch._Flight(JOB, None, Path("fresh.ipynb"), deadline=time.monotonic() + 3600)  # type: ignore[arg-type]
    held = dispatch.Dispatcher.__new__(dispatch.Dispatcher)
    held.out = {Future("late"): late, Future("fresh"): fresh}
    held._error = lambda flight, exc: str(exc)  # type: ignore[method-assign]
    held._record = lambda flight, result: recorded.append((flight, result))  # type: ignore[method-assign]
    held._fail_overdue()
    assert cancelled == ["late"] and [f for f, _ in recorded] == [late]
    assert "time budget" in recorded[0][1]
    assert list(held.out.values()) == [fresh]
