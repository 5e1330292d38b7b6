"""The service as an LTI 1.3 tool, against a platform built on lti1p3platform (tests/service/lti_platform.py).

In headless Chromium: an instructor deep-links an assignment, a student launches it,
uploads a notebook, and the score that counts arrives at the platform's line item;
an instructor's launch adds the LMS course's members without changing anyone's token;
forged launches (bad signature, wrong audience, expired, wrong deployment) and a
replayed one are refused with a page naming what was wrong. Over HTTP, on SQLite and
PostgreSQL: a score queued while the platform is down arrives after a service restart.
"""

from __future__ import annotations

import datetime as dt
import re
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import httpx
import pytest
import svc_support as support
from conftest import iso
from lti_platform import FORGERIES, Platform
from sqlalchemy import create_engine, text

SOLUTION = (support.HULL_EXAMPLES / "solution.ipynb").read_bytes()
WRONG = (support.HULL_EXAMPLES / "wrong-clockwise.ipynb").read_bytes()
ROSTER = [("tess", "Tess TA", "tess@example.edu", "ta")]


def lti_course(folder: Path, platform: Platform) -> Path:
    now = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    body = f"""
[course]
name = "LTI course"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "hull"
title = "Convex hull"
opens = 2020-01-01T00:00:00Z
deadline = {iso(now + dt.timedelta(days=30))}
count = "best"

{platform.course_toml()}
"""
    return support.write_course(folder, body=body, roster=ROSTER)


def wait_until(check: Callable[[], Any], what: str, timeout: float = 600.0) -> Any:
    deadline = time.monotonic() + timeout
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout:.0f} s for {what}")
        time.sleep(0.3)


def pair(folder: Path, database: str) -> tuple[support.Server, Platform]:
    port = support.free_port()
    platform = Platform(tool=f"http://127.0.0.1:{port}", port=support.free_port())
    platform.add_person("prof-1", "Prof Ada", "ada@example.edu", "Instructor")
    platform.add_person("ta-1", "Theo TA", "theo@example.edu", "TeachingAssistant")
    platform.add_person("student-1", "Alice", "alice@example.edu", "Learner")
    platform.add_person("student-2", "Bob", "bob@example.edu", "Learner")
    server = support.Server(lti_course(folder, platform), database, port=port, jobs=1)
    return server, platform


@pytest.fixture(scope="module")
def lti(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[support.Server, Platform]]:
    folder = tmp_path_factory.mktemp("lti")
    server, platform = pair(folder, f"sqlite:///{folder / 'lti.sqlite3'}")
    platform.start()
    server.start()
    try:
        yield server, platform
    finally:
        server.stop()
        platform.stop()


def launch(web: support.WebDriver, platform: Platform, sub: str, query: str) -> None:
    web.run("document.cookie.split(';').forEach(c => document.cookie = c.split('=')[0] + "
            "'=; expires=Thu, 01 Jan 1970 00:00:00 GMT; path=/')")
    web.command("DELETE", "/cookie")
    web.open(f"{platform.url}/launch/{sub}?{query}")
    web.wait_for("return document.readyState === 'complete' && "
                 f"!location.href.startsWith('{platform.url}/launch') && "
                 "!location.pathname.startsWith('/lti/login') && "
                 "!location.pathname.startsWith('/authorize') && "
                 "document.querySelector('form#form') === null", timeout=120)


def page_text(web: support.WebDriver) -> str:
    return web.run("return document.body.innerText")


@pytest.mark.browser
def test_deep_link_launch_upload_and_score(lti: tuple[support.Server, Platform],
                                           browser: support.WebDriver, tmp_path: Path) -> None:
    server, platform = lti
    launch(browser, platform, "prof-1", "deep_link=true")
    assert "/lti/deep-link/" in browser.url, page_text(browser)
    browser.click("#choose")
    browser.wait_for("return document.getElementById('return') !== null", timeout=60)
    browser.click("#return")
    browser.wait_for("return document.getElementById('added') !== null", timeout=60)
    (item,) = platform.course.deep_linked
    assert item["type"] == "ltiResourceLink" and item["custom"] == {"assignment": "hull"}
    link = next(k for k, v in platform.course.links.items() if v["custom"] == {"assignment": "hull"})
    lineitem = platform.course.links[link]["lineitem"]

    launch(browser, platform, "student-1", f"link={link}")
    assert browser.url.endswith("/assignments/hull"), page_text(browser)
    notebook = tmp_path / "hull.ipynb"
    notebook.write_bytes(WRONG)
    browser.type("#notebook", str(notebook))
    browser.click("#submit")
    scores = wait_until(lambda: platform.course.scores.get(lineitem), "the score at the platform")
    engine = create_engine(server.database)
    try:
        with engine.connect() as db:
            user, score, top = db.execute(text(
                "SELECT u.id, s.score, s.max_score FROM submissions s JOIN users u ON u.id = s.user_id "
                "JOIN lti_accounts a ON a.user_id = u.id WHERE a.sub = 'student-1'")).one()
    finally:
        engine.dispose()
    sent = scores[-1]
    assert 0 < sent["scoreGiven"] < sent["scoreMaximum"] == top == 38
    assert sent["scoreGiven"] == pytest.approx(score)
    assert sent["userId"] == "student-1" and sent["gradingProgress"] == "FullyGraded"
    assert sent["activityProgress"] == "Completed" and sent["timestamp"]
    # what the instructor reads in the platform's gradebook (docs/lti.md, "Trying it locally")
    browser.open(f"{platform.url}/gradebook")
    row = next(line for line in browser.text("table").splitlines() if "student-1" in line)
    assert f"{sent['scoreGiven']} / 38" in row


@pytest.mark.browser
def test_instructor_launch_adds_the_lms_roster_and_keeps_tokens(
        lti: tuple[support.Server, Platform], browser: support.WebDriver) -> None:
    server, platform = lti
    link = platform.add_link({"assignment": "hull"}, title="hull by hand")
    launch(browser, platform, "prof-1", f"link={link}")
    assert "/instructor" in browser.url and "roster-" in browser.url, page_text(browser)
    engine = create_engine(server.database)
    try:
        with engine.connect() as db:
            roles = dict(db.execute(text(
                "SELECT a.sub, u.role FROM lti_accounts a JOIN users u ON u.id = a.user_id")).all())
    finally:
        engine.dispose()
    assert roles == {"prof-1": "instructor", "ta-1": "ta", "student-1": "student",
                     "student-2": "student"}
    token = server.tokens()["tess"]  # a roster entry of the CSV: its token still opens the service
    answer = httpx.get(f"{server.url}/api/submissions/999999",
                       headers={"Authorization": f"Bearer {token}"})
    assert answer.status_code == 404, answer.text  # signed in (a wrong token gets 401)


@pytest.mark.browser
@pytest.mark.parametrize("forgery, words", [
    ("bad-signature", "signature does not match"),
    ("wrong-audience", "client id (audience, aud)"),
    ("expired", "has expired"),
    ("wrong-deployment", "deployment id is not one of"),
])
def test_forged_launches_are_refused(lti: tuple[support.Server, Platform],
                                     browser: support.WebDriver, forgery: str, words: str) -> None:
    server, platform = lti
    assert forgery in FORGERIES
    link = platform.add_link({"assignment": "hull"})
    launch(browser, platform, "student-2", f"link={link}&forge={forgery}")
    shown = page_text(browser)
    assert words in shown and "Traceback" not in shown, shown
    assert not browser.url.endswith("/assignments/hull")


@pytest.mark.browser
def test_a_replayed_launch_is_refused(lti: tuple[support.Server, Platform],
                                      browser: support.WebDriver) -> None:
    server, platform = lti
    link = platform.add_link({"assignment": "hull"})
    launch(browser, platform, "student-2", f"link={link}")
    assert browser.url.endswith("/assignments/hull"), page_text(browser)
    browser.command("DELETE", "/cookie/ag_session")
    browser.open(f"{platform.url}/replay/student-2")
    browser.wait_for("return location.pathname === '/lti/launch' && document.readyState === 'complete'",
                     timeout=60)
    assert "already used" in page_text(browser)


# -- the outbox across a restart, without a browser -------------------------------------

def http_launch(client: httpx.Client, platform: Platform, sub: str, link: str) -> httpx.Response:
    """The browser's part of a launch: follow the redirects, post the launch form."""
    form = client.get(f"{platform.url}/launch/{sub}?link={link}", follow_redirects=True)
    action = re.search(r'action="([^"]+)"', form.text).group(1)
    fields = dict(re.findall(r'name="(id_token|state)" value="([^"]+)"', form.text))
    return client.post(action, data=fields, follow_redirects=True)


def test_a_score_queued_while_the_lms_is_down_arrives_after_a_restart(
        database: Callable[[str], str], tmp_path: Path) -> None:
    server, platform = pair(tmp_path, database("lti_restart"))
    link = platform.add_link({"assignment": "hull"})
    lineitem = platform.course.links[link]["lineitem"]
    platform.start()
    server.start()
    engine = create_engine(server.database)
    try:
        with httpx.Client(timeout=60) as client:
            page = http_launch(client, platform, "student-1", link)
            assert page.url.path == "/assignments/hull", page.text
            platform.stop()  # the LMS goes down before the score is sent
            csrf = re.search(r'name="csrf" value="([^"]+)"', page.text).group(1)
            answer = client.post(f"{server.url}/assignments/hull/submissions", data={"csrf": csrf},
                                 files={"notebook": ("hull.ipynb", SOLUTION)},
                                 headers={"Accept": "application/json"})
            assert answer.status_code in (200, 201, 202, 303), answer.text

        def tried() -> bool:
            with engine.connect() as db:
                return bool(db.execute(text("SELECT count(*) FROM lti_scores WHERE state = 'pending' "
                                            "AND tries >= 1")).scalar_one())
        wait_until(tried, "a failed try of the score while the platform is down")
        server.stop()
        assert not platform.course.scores.get(lineitem)
        platform.start()
        server.start()
        scores = wait_until(lambda: platform.course.scores.get(lineitem), "the score after restart")
        assert scores[-1]["scoreGiven"] == scores[-1]["scoreMaximum"] == 38

        # The outbox marks the row sent after the platform has answered: wait for the
        # commit rather than read the row the moment the platform holds the score.
        def states() -> list[str]:
            with engine.connect() as db:
                found = db.execute(text("SELECT state FROM lti_scores")).scalars().all()
            return found if found and set(found) == {"sent"} else []
        wait_until(states, "the score marked sent in the outbox")
        assert len(platform.course.scores[lineitem]) == 1, "the score was posted more than once"
    finally:
        engine.dispose()
        server.stop()
        platform.stop()
