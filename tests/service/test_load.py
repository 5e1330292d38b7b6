"""300 uploads from 60 students at once, the service SIGKILLed in the middle and started again.

Every acknowledged upload must be in the database and graded exactly once:
one ``grade`` job per submission, that job finished, and one row for it in the
``gradings`` ledger (a grading cut off by the kill leaves no row; the job's
lease runs out and another grading process takes it). Uploads whose answer was
lost in the kill are retried by the client, as a person would; such a retry may
add an attempt, never lose one.

To keep the run short on 2 busy cores the assignment runs its public checks
only (``public_only = true`` in the course file) on small hull notebooks.
"""

from __future__ import annotations

import datetime as dt
import shutil
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Callable, Iterator

import httpx
import pytest
import svc_support as support
from conftest import iso
from sqlalchemy import create_engine, text

from autograder.sandbox import tempdirs

STUDENTS = 60
PER_STUDENT = 5
KILL_AFTER = 120  # acknowledged uploads before the SIGKILL
NOTEBOOKS = [(support.HULL_EXAMPLES / n).read_bytes()
             for n in ("partial-only-orientation.ipynb", "wrong-clockwise.ipynb",
                       "wrong-keeps-collinear.ipynb")]

pytestmark = pytest.mark.slow


def load_course(folder: Path) -> Path:
    now = dt.datetime.now(dt.timezone.utc)
    body = f"""
[course]
name = "Load"
roster = "roster.csv"
data = "data"
submissions_per_hour = {PER_STUDENT * 2}

[[assignment]]
name = "hull"
opens = 2020-01-01T00:00:00Z
deadline = {iso(now + dt.timedelta(days=30))}
public_only = true
"""
    roster = [(f"s{i:02d}", f"Student {i}", f"s{i}@example.edu", "student") for i in range(STUDENTS)]
    return support.write_course(folder, body=body, roster=roster)


@pytest.fixture
def own_tmpdir(monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """``TMPDIR`` for the service this test starts: a folder of the test's own.

    The service's slot folders go there, so graders running on the same machine (their
    folders in the shared /tmp) count for nothing in what the test counts. It is
    world-traversable, as /tmp is: the slots' users must reach their folders.
    """
    folder = Path(tempfile.mkdtemp(prefix="numgrade-load-test-"))
    folder.chmod(0o755)
    monkeypatch.setenv("TMPDIR", str(folder))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def test_300_uploads_sigkill_and_restart_each_graded_once(database: Callable[[str], str],
                                                         tmp_path: Path, own_tmpdir: Path,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    scratch = own_tmpdir
    url = database("load")
    server = support.Server(load_course(tmp_path / "course"), url, jobs=2, lease=5.0).start()
    tokens = server.tokens()
    acked: dict[int, str] = {}
    lock = threading.Lock()
    killed = threading.Event()
    restarted = threading.Event()
    orphans: list[int] = []  # the killed service's grading processes: they must not outlive it

    def send(index: int) -> None:
        student = f"s{index % STUDENTS:02d}"
        data = NOTEBOOKS[index % len(NOTEBOOKS)] + b" " * (index % 7)  # some identical, some not
        while True:
            try:
                with httpx.Client(timeout=120) as client:
                    answer = support.upload(client, server.url, tokens[student], "hull", data)
                assert answer.status_code == 201, answer.text
                with lock:
                    acked[answer.json()["id"]] = student
                    if len(acked) >= KILL_AFTER and not killed.is_set():
                        killed.set()
                        orphans.extend(server.kill())
                        server.start()
                        restarted.set()
                return
            except httpx.TransportError:  # the service was killed under us: retry when it is back
                restarted.wait(support.START_TIMEOUT)
                time.sleep(0.2)

    try:
        with ThreadPoolExecutor(max_workers=30) as pool:
            list(pool.map(send, range(STUDENTS * PER_STUDENT)))
        assert killed.is_set()
        engine = create_engine(url)
        deadline = time.monotonic() + 900
        while time.monotonic() < deadline:
            with engine.connect() as db:
                left = db.execute(text("SELECT count(*) FROM jobs WHERE state IN ('queued', 'running')")).scalar_one()
            if not left:
                break
            time.sleep(1)
        with engine.connect() as db:
            subs = dict(db.execute(text("SELECT id, user_id FROM submissions")).all())
            states = dict(db.execute(text("SELECT id, status FROM submissions")).all())
            jobs = db.execute(text("SELECT submission_id, state, id FROM jobs WHERE kind = 'grade'")).all()
            ledger = db.execute(text("SELECT job_id, count(*) FROM gradings GROUP BY job_id")).all()
        engine.dispose()
    finally:
        server.stop()
    assert orphans and not [pid for pid in orphans if support.alive(pid)], \
        "grading processes of the killed service are still running"
    # The killed service's graders could not remove their slot folders. Nobody holds
    # their locks, so they are abandoned: the next run removes them once they are older
    # than GRACE_SECONDS. Here that is done at once, and nothing else of this test is left.
    monkeypatch.setattr(tempdirs, "GRACE_SECONDS", 0.0)
    tempdirs.remove_abandoned(scratch, prefix="autograder-slot-")
    assert not list(scratch.glob("autograder-slot-*")), "a slot folder is still held"
    assert left == 0, f"{left} jobs still waiting after 15 minutes"
    assert len(acked) == STUDENTS * PER_STUDENT
    for sub_id, student in acked.items():  # nothing acknowledged was lost or mixed up
        assert subs.get(sub_id) == student
    assert len(subs) - len(acked) <= 30, "retries after the kill added more attempts than were in flight"
    assert set(states.values()) == {"graded"}, states
    per_submission: dict[int, int] = {}
    for submission_id, state, _ in jobs:
        per_submission[submission_id] = per_submission.get(submission_id, 0) + 1
        assert state == "done"
    assert set(per_submission) == set(subs) and set(per_submission.values()) == {1}
    assert {count for _, count in ledger} == {1} and len(ledger) == len(subs)
