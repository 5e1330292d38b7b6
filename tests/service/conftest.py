"""Fixtures of the service tests: the database backends, a running class server, a browser.

Every test here talks to a real ``autograder serve`` on 127.0.0.1 (a free port),
once with SQLite and once with PostgreSQL (a cluster started in a temporary
folder with ``initdb``/``pg_ctl`` as the ``postgres`` user; the PostgreSQL runs
skip, saying why, only where PostgreSQL is not installed).
"""

from __future__ import annotations

import datetime as dt
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Callable

import pytest

pytest.importorskip("fastapi", reason="the service extra is not installed: pip install -e '.[service,postgres]'")

from sqlalchemy import create_engine  # noqa: E402
from sqlalchemy.engine import Engine  # noqa: E402

import svc_support as support  # noqa: E402

STAFF = [("tess", "Tess TA", "tess@example.edu", "ta"),
         ("prof", "Prof Ada", "ada@example.edu", "instructor")]
CLASS = [("alice", "Alice", "alice@example.edu", "student"),
         ("bob", "Bob", "bob@example.edu", "student"),
         ("carol", "Carol", "carol@example.edu", "student"),
         ("dave", "Dave", "dave@example.edu", "student"),
         ("eve", "Eve", "eve@example.edu", "student")] + STAFF
#: uploads per student and hour in the class course (eve reaches it in the access tests)
PER_HOUR = 4
MAX_BYTES = 100_000


def iso(when: dt.datetime) -> str:
    return when.strftime("%Y-%m-%dT%H:%M:%SZ")


@pytest.fixture(scope="session")
def postgres() -> Iterator[support.PostgresCluster]:
    try:
        cluster = support.start_postgres()
    except RuntimeError as exc:
        pytest.skip(f"PostgreSQL runs skipped: {exc}")
    try:
        yield cluster
    finally:
        cluster.stop()


@pytest.fixture(scope="session", params=["sqlite", "postgresql"])
def database(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
             ) -> Callable[[str], str]:
    """A function making a fresh, empty database URL of the backend under test."""
    if request.param == "sqlite":
        folder = tmp_path_factory.mktemp("sqlite")
        return lambda name: f"sqlite:///{folder / name}.sqlite3"
    cluster = request.getfixturevalue("postgres")
    return cluster.create_database


def class_course(folder: Path) -> Path:
    """hull due an hour ago (bob and eve have extensions), one closed long ago, one not open yet."""
    now = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    body = f"""
[course]
name = "Service test course"
roster = "roster.csv"
data = "data"
submissions_per_hour = {PER_HOUR}
max_upload_bytes = {MAX_BYTES}

[[assignment]]
name = "hull"
title = "Convex hull"
opens = 2020-01-01T00:00:00Z
deadline = {iso(now - dt.timedelta(hours=1))}
late_penalty_per_day = 0.1
max_late_days = 3
count = "last"
[assignment.extensions]
bob = {iso(now + dt.timedelta(days=30))}
eve = {iso(now + dt.timedelta(days=30))}
dave = {iso(now + dt.timedelta(days=30))}

[[assignment]]
name = "old"
assignment = "hull"
opens = 2020-01-01T00:00:00Z
deadline = 2020-02-01T00:00:00Z

[[assignment]]
name = "broken"
assignment = "./broken-hull"
opens = 2020-01-01T00:00:00Z
deadline = 2099-02-01T00:00:00Z

[[assignment]]
name = "later"
assignment = "hull"
opens = 2099-01-01T00:00:00Z
deadline = 2099-02-01T00:00:00Z
"""
    broken = folder / "broken-hull"  # hull with a hidden check that cannot be collected
    shutil.copytree(support.ROOT / "assignments" / "hull", broken)
    for check in (broken / "checks" / "hidden").glob("test_*.py"):
        check.rename(check.with_suffix(".ok"))
        check.write_text("def broken(:\n")
    return support.write_course(folder, body=body, roster=CLASS)


class Running:
    """The class server of one backend, with its tokens and a database handle."""

    def __init__(self, server: support.Server) -> None:
        self.server = server
        self.url = server.url
        self.tokens = server.tokens()
        self.engine: Engine = create_engine(server.database)
        self.data = server.course.parent / "data"


@pytest.fixture(scope="session")
def service(database: Callable[[str], str], tmp_path_factory: pytest.TempPathFactory
            ) -> Iterator[Running]:
    folder = tmp_path_factory.mktemp("class")
    server = support.Server(class_course(folder), database("class"))
    server.start()
    running = Running(server)
    try:
        yield running
    finally:
        running.engine.dispose()
        server.stop()


@pytest.fixture(scope="session")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[support.WebDriver]:
    if not (support.CHROMIUM and support.CHROMEDRIVER):
        pytest.skip("headless Chromium is not installed: apt-get install chromium chromium-driver "
                    "(.ci/run does this in CI)")
    driver, web = support.start_chromedriver(tmp_path_factory.mktemp("chromium"))
    try:
        yield web
    finally:
        web.quit()
        driver.terminate()
        try:
            driver.wait(timeout=10)
        except subprocess.TimeoutExpired:
            driver.kill()
