"""An upload wakes the idle grading processes at once, instead of at their next poll.

The grading processes look for work every ``poll_seconds`` (0.2 s); with
nothing else, an upload to an idle service waited up to that long before a
grader took it. ``jobqueue.wake_on_enqueue`` (set by ``autograder serve`` to its
pool's event) is called once a transaction that queued a job has committed, and an
idle grader waits on that event. Here the poll is an hour, so only the wake-up can
end a wait.
"""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

pytest.importorskip("sqlalchemy")

from autograder.service import auth, jobqueue  # noqa: E402
from autograder.service.db import make_engine, sessions, upgrade  # noqa: E402
from autograder.service.graders import idle  # noqa: E402
from autograder.service.models import Submission  # noqa: E402

HOUR = 3600.0


def test_a_job_wakes_the_graders_once_its_transaction_commits(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'course.db'}")
    upgrade(engine)
    factory = sessions(engine)
    with factory.begin() as session:
        auth.import_roster(session, [auth.RosterEntry("alice", "Alice", "a@x", "student")])
    woken: list[int] = []
    jobqueue.wake_on_enqueue(lambda: woken.append(len(woken)))
    try:
        def queue_one(commit: bool) -> None:
            session = factory()
            with session:
                submission = Submission(user_id="alice", assignment="hull", sha256="0" * 64,
                                        filename="hull.ipynb")
                session.add(submission)
                session.flush()
                before = len(woken)
                jobqueue.enqueue(session, submission.id)
                session.flush()
                assert len(woken) == before  # not before the commit: the job is not visible yet
                (session.commit if commit else session.rollback)()
                assert len(woken) == before + (1 if commit else 0)

        queue_one(commit=False)  # rolled back: nothing to grade, nobody woken
        assert woken == []
        queue_one(commit=True)
        queue_one(commit=True)  # every commit that queued a job wakes them again
        assert len(woken) == 2
        with factory() as session:  # one session, several transactions: one wake-up each
            for k in range(3):
                submission = Submission(user_id="alice", assignment="hull", sha256=f"{k}" * 64,
                                        filename="hull.ipynb")
                session.add(submission)
                session.flush()
                jobqueue.enqueue(session, submission.id)
                jobqueue.enqueue(session, submission.id)  # two jobs, one commit: one wake-up
                (session.rollback if k == 1 else session.commit)()
            session.commit()  # nothing queued since: nobody woken
        assert len(woken) == 4
        jobqueue.wake_on_enqueue(None)
        queue_one(commit=False)
        with factory.begin() as session:  # without a wake-up set, queuing still works
            submission = Submission(user_id="alice", assignment="hull", sha256="1" * 64,
                                    filename="hull.ipynb")
            session.add(submission)
            session.flush()
            jobqueue.enqueue(session, submission.id)
        assert len(woken) == 4
    finally:
        jobqueue.wake_on_enqueue(None)
        engine.dispose()


@pytest.mark.parametrize("ends", ["wake", "stop-without-wake"])
def test_an_idle_grader_looks_again_when_woken(ends: str) -> None:
    stop, wake = threading.Event(), threading.Event()
    with_wake = ends == "wake"
    waiting = threading.Thread(target=idle, args=(stop, wake if with_wake else None, HOUR),
                               daemon=True)
    waiting.start()
    (wake if with_wake else stop).set()
    waiting.join(60)
    assert not waiting.is_alive(), "the grader slept through the wake-up"
    assert not wake.is_set()  # cleared by the grader that woke: the next wait is a real one
