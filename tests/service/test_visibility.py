"""The four visibility levels of a check, before and after the student's deadline.

A real server on loopback grades the same wrong notebook for two students: ann's
deadline is ahead, pat's has passed. The feedback page is rendered when it is
viewed, so moving ann's deadline into the past (an extension row) shows her the
"after_deadline" check without a regrade.
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path
from typing import Iterator

import httpx
import nbformat
import pytest
import svc_support as support
from sqlalchemy import create_engine, text
from test_flows import sign_in

CHECKS = '''\
import pytest


@pytest.mark.visibility("hidden")
def test_level_hidden(student):
    assert student.double(21) == 42, "SECRET-HIDDEN expected 42"


@pytest.mark.visibility("after_deadline")
def test_level_after(student):
    assert student.double(21) == 42, "SECRET-AFTER expected 42"


@pytest.mark.visibility("input")
def test_level_input(student, feedback):
    feedback.input("x = 21 (INPUT-SHOWN)")
    assert student.double(21) == 42, "SECRET-INPUT expected 42"


@pytest.mark.visibility("visible")
def test_level_visible(student):
    assert student.double(21) == 42, "SHOWN-VISIBLE expected 42"
'''
WRONG = "def double(x):\n    return 0\n"


def iso(when: dt.datetime) -> str:
    return when.strftime("%Y-%m-%dT%H:%M:%SZ")


def write_levels(folder: Path) -> None:
    (folder / "checks" / "hidden").mkdir(parents=True)
    (folder / "checks" / "public").mkdir(parents=True)
    (folder / "assignment.toml").write_text('[assignment]\nname = "levels"\n')
    cell = nbformat.v4.new_code_cell(
        "### BEGIN SOLUTION\ndef double(x):\n    return 2 * x\n### END SOLUTION",
        metadata={"nbgrader": {"grade_id": "double", "solution": True, "grade": False,
                               "locked": False, "schema_version": 3}})
    nbformat.write(nbformat.v4.new_notebook(cells=[cell]), folder / "levels.ipynb")
    (folder / "checks" / "hidden" / "test_levels.py").write_text(CHECKS)


@pytest.fixture(scope="module")
def levels(tmp_path_factory: pytest.TempPathFactory) -> Iterator[support.Server]:
    folder = tmp_path_factory.mktemp("levels")
    write_levels(folder / "levels")
    now = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    body = f"""
[course]
name = "Visibility course"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "levels"
assignment = "./levels"
opens = 2020-01-01T00:00:00Z
deadline = {iso(now + dt.timedelta(days=2))}
max_late_days = 3
[assignment.extensions]
pat = {iso(now - dt.timedelta(hours=1))}
"""
    course = support.write_course(folder, body=body, roster=[
        ("ann", "Ann", "ann@example.org", "student"), ("pat", "Pat", "pat@example.org", "student")])
    server = support.Server(course, f"sqlite:///{folder / 'db.sqlite3'}", jobs=1)
    server.start()
    try:
        yield server
    finally:
        server.stop()


def graded(server: support.Server, who: str) -> int:
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(WRONG)])
    with httpx.Client(timeout=120) as client:
        answer = support.upload(client, server.url, server.tokens()[who], "levels",
                                json.dumps(nb).encode(), name="levels.ipynb")
        assert answer.status_code in (200, 201, 202), answer.text
        sub_id = answer.json()["id"]
        view = support.wait_graded(client, server.url, server.tokens()[who], sub_id)
    assert view["status"] == "graded", view
    return int(sub_id)


def page_text(browser: support.WebDriver, server: support.Server, who: str, sub_id: int) -> str:
    browser.command("DELETE", "/cookie")  # sign the previous student out
    sign_in(browser, server.url, server.tokens()[who])
    browser.open(f"{server.url}/submissions/{sub_id}/feedback")
    browser.wait_for("return document.body && document.body.innerText.includes('level_visible')",
                     timeout=60)
    return browser.text("body")


@pytest.mark.browser
def test_the_four_levels_before_and_after_the_deadline(levels: support.Server,
                                                       browser: support.WebDriver) -> None:
    ann, pat = graded(levels, "ann"), graded(levels, "pat")
    before = page_text(browser, levels, "ann", ann)
    after = page_text(browser, levels, "pat", pat)
    for page in (before, after):
        assert "level_hidden" in page and "SECRET-HIDDEN" not in page      # name and status only
        assert "INPUT-SHOWN" in page and "SECRET-INPUT" not in page        # input, not expected
        assert "SHOWN-VISIBLE" in page                                     # in full
    assert "level_after" in before and "SECRET-AFTER" not in before
    assert "SECRET-AFTER" in after
    # ann's deadline passes (an extension moved into the past): no regrade, the page changes
    engine = create_engine(levels.database)
    with engine.begin() as db:
        db.execute(text("INSERT INTO extensions (user_id, assignment, deadline) "
                        "VALUES ('ann', 'levels', :when)"),
                   {"when": dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)
                    - dt.timedelta(minutes=1)})
    engine.dispose()
    assert "SECRET-AFTER" in page_text(browser, levels, "ann", ann)


def test_gradescope_gets_its_own_visibility_and_cut_outputs() -> None:
    from autograder.results.feedback import as_students_see
    from autograder.results.model import CheckResult, SubmissionResult

    checks = tuple(CheckResult(name=level, score=0.0, max_score=1.0, output=f"SECRET {level}",
                               hidden=True, kind="wrong", level=level, shown_input="x = 21")
                   for level in ("hidden", "after_deadline", "input", "visible"))
    result = SubmissionResult(id="ann", source="", assignment="levels", key="", sha256="",
                              outcome="graded", output="", tests=checks, execution_time=0.0,
                              seed=0)
    shown = as_students_see(result, past_deadline=True).to_dict()["tests"]
    assert [t["visibility"] for t in shown] == ["visible", "after_due_date", "visible", "visible"]
    assert [("SECRET" in t["output"]) for t in shown] == [False, True, False, True]
    assert shown[2]["output"] == "Input: x = 21"
