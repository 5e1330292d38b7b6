"""``GET /api/submissions/ID?wait=S``: the answer comes once the attempt is graded, not after
the client asked again and again.

The waiting request is woken by the grading processes (:mod:`autograder.service.waits`);
without them (an app made here, with no pool) it looks at the database itself now and
then. The grade is recorded here from another thread, as a grading process would.
"""

from __future__ import annotations

import asyncio
import csv
import multiprocessing
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import class_course

pytest.importorskip("fastapi")

from fastapi.testclient import TestClient  # noqa: E402

from autograder.service import jobqueue  # noqa: E402
from autograder.service.app import create_app  # noqa: E402
from autograder.service.db import make_engine, sessions  # noqa: E402
from autograder.service.models import Submission  # noqa: E402
from autograder.service.server import import_roster, open_course  # noqa: E402
from autograder.service.waits import Waits  # noqa: E402

HOUR = 3600.0


def headers(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}", "Accept": "application/json"}


@pytest.fixture
def course(tmp_path: Path) -> Iterator[tuple[Any, Any, dict[str, str], int]]:
    """A course with one queued attempt of alice's: (course, session factory, tokens, its id)."""
    database = f"sqlite:///{tmp_path / 'waits.sqlite3'}"
    found = open_course(class_course(tmp_path), database=database)
    import_roster(found, found.roster)
    with (found.data_dir / "tokens.csv").open() as handle:
        tokens = {row["id"]: row["token"] for row in csv.DictReader(handle)}
    engine = make_engine(database)
    factory = sessions(engine)
    with factory.begin() as session:
        sub = Submission(user_id="alice", assignment="hull", sha256="0" * 64,
                         filename="hull.ipynb", status="queued")
        session.add(sub)
        session.flush()
        jobqueue.enqueue(session, sub.id)
        sub_id = sub.id
    yield found, factory, tokens, sub_id
    engine.dispose()


def grade_later(factory: Any, sub_id: int, after: float, waits: Waits | None = None) -> threading.Thread:
    """Record the attempt as graded after ``after`` seconds, and tell ``waits``."""
    def run() -> None:
        time.sleep(after)
        with factory.begin() as session:
            sub = session.get(Submission, sub_id)
            sub.status, sub.outcome, sub.score, sub.max_score = "graded", "graded", 38.0, 38.0
        if waits is not None:
            waits.finished(sub_id)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize("woken", [True, False], ids=["woken-by-the-graders", "looking-itself"])
def test_a_waiting_request_answers_once_the_attempt_is_graded(course: Any, woken: bool) -> None:
    found, factory, tokens, sub_id = course
    waits = Waits() if woken else None
    with TestClient(create_app(found, factory, waits=waits)) as client:
        url = f"/api/submissions/{sub_id}"
        assert client.get(url, headers=headers(tokens["alice"])).json()["status"] == "queued"
        grade_later(factory, sub_id, 0.5, waits)
        view = client.get(f"{url}?wait=50", headers=headers(tokens["alice"])).json()
        assert view["status"] == "graded" and view["score"] is not None
        # graded already: a wait answers at once, whatever it asks
        assert client.get(f"{url}?wait=50", headers=headers(tokens["alice"])).json()["status"] == "graded"


def test_a_wait_ends_after_its_seconds(course: Any) -> None:
    found, factory, tokens, sub_id = course
    with TestClient(create_app(found, factory, waits=Waits())) as client:
        view = client.get(f"/api/submissions/{sub_id}?wait=0.3", headers=headers(tokens["alice"]))
        assert view.status_code == 200 and view.json()["status"] == "queued"


@pytest.mark.parametrize("wait", ["61", "-1", "nan", "inf", "1e400", "soon"])
def test_a_wait_out_of_bounds_is_refused(course: Any, wait: str) -> None:
    found, factory, tokens, sub_id = course
    with TestClient(create_app(found, factory, waits=Waits())) as client:
        answer = client.get(f"/api/submissions/{sub_id}?wait={wait}", headers=headers(tokens["alice"]))
        assert answer.status_code == 422


def test_a_wait_on_someone_elses_attempt_is_a_404_at_once(course: Any) -> None:
    found, factory, tokens, sub_id = course
    with TestClient(create_app(found, factory, waits=Waits())) as client:
        answer = client.get(f"/api/submissions/{sub_id}?wait=50", headers=headers(tokens["bob"]))
        assert answer.status_code == 404


def test_the_relay_wakes_only_the_requests_of_the_graded_attempt() -> None:
    waits = Waits()
    queue = multiprocessing.get_context("spawn").Queue()
    relay = waits.relay(queue)

    async def both() -> list[str]:
        ended: list[str] = []

        async def wait_for(sub_id: int) -> None:
            await waits.wait(sub_id, HOUR if sub_id == 7 else 1.0)
            ended.append(str(sub_id))

        tasks = [asyncio.create_task(wait_for(7)), asyncio.create_task(wait_for(8))]
        await asyncio.sleep(0.2)
        queue.put("junk")  # not an id: ignored
        queue.put(7)       # as a grading process does
        done, _ = await asyncio.wait(tasks, timeout=60)
        assert len(done) == 2, "a waiting request slept through its grade"
        return ended

    assert asyncio.run(both()) == ["7", "8"]  # 7 woken at once, 8 at the end of its second
    queue.put(None)
    relay.join(60)
    assert not relay.is_alive()
