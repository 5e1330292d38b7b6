"""Every page of the service for everyone: axe-core at WCAG 2.1 AA, the keyboard alone, a phone.

A real server on loopback (the class course of ``conftest.py``), headless
Chromium over WebDriver, and the real axe-core script (``tests/support/axe.py``).
Then the rough edges: attempts numbered per student, the deadline's wording, a
confirmation after a regrade, the Canvas ID column, the released notebook.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import json
import re
from pathlib import Path

import httpx
import pytest
import svc_support as support
from conftest import Running
from sqlalchemy import text
from test_flows import sign_in

from tests.support import axe

SOLUTION = (support.HULL_EXAMPLES / "solution.ipynb").read_bytes()


axe_js = axe.axe_js


def sign_out(web: support.WebDriver) -> None:
    web.open("about:blank")
    web.command("DELETE", "/cookie")


def as_user(web: support.WebDriver, service: Running, who: str) -> None:
    sign_out(web)
    sign_in(web, service.url, service.tokens[who])


@pytest.fixture(scope="module")
def graded(service: Running) -> int:
    """A graded attempt of alice on hull (its id)."""
    with httpx.Client(timeout=60) as client:
        sub = support.upload(client, service.url, service.tokens["alice"], "hull", SOLUTION).json()
        view = support.wait_graded(client, service.url, service.tokens["alice"], sub["id"])
    assert view["status"] == "graded", view
    return int(sub["id"])


def student_pages(url: str, sub_id: int) -> list[str]:
    return [f"{url}/assignments", f"{url}/assignments/hull", f"{url}/assignments/old",
            f"{url}/submissions/{sub_id}", f"{url}/submissions/999999"]


def staff_pages(url: str, sub_id: int) -> list[str]:
    return [f"{url}/instructor", f"{url}/instructor/students/alice",
            f"{url}/instructor/hull/grading", f"{url}/instructor/submissions/{sub_id}",
            f"{url}/instructor/regrade-requests"]


def sandboxed_copies(service: Running, sub_id: int, folder: Path) -> list[str]:
    """The pages served under ``CSP: sandbox`` (feedback, summaries), saved as files.

    A sandboxed page runs no script, and WebDriver's scripts there never see a timer
    fire, so axe (which waits on timers) cannot finish in it: the same bytes are
    checked from a file instead.
    """
    pages = {"feedback": (f"/submissions/{sub_id}/feedback", "alice"),
             "summary": ("/instructor/hull/summary/", "prof"),
             "summary-feedback": ("/instructor/hull/summary/alice/feedback.html", "prof")}
    urls = []
    with httpx.Client(base_url=service.url, timeout=60) as client:
        for name, (path, who) in pages.items():
            answer = client.get(path, headers={"Authorization": f"Bearer {service.tokens[who]}"})
            assert answer.status_code == 200 and "sandbox" in answer.headers["content-security-policy"]
            (folder / f"{name}.html").write_bytes(answer.content)
            urls.append((folder / f"{name}.html").as_uri())
    return urls


@pytest.mark.browser
def test_every_page_passes_axe_and_fits_a_phone(service: Running, browser: support.WebDriver,
                                                axe_js: str, graded: int, tmp_path: Path) -> None:
    problems = []
    for url in sandboxed_copies(service, graded, tmp_path):
        problems += axe.page_problems(browser, axe_js, url)
    sign_out(browser)
    problems += axe.page_problems(browser, axe_js, f"{service.url}/login")
    as_user(browser, service, "alice")
    for url in student_pages(service.url, graded):
        problems += axe.page_problems(browser, axe_js, url)
    as_user(browser, service, "prof")
    for url in staff_pages(service.url, graded):
        problems += axe.page_problems(browser, axe_js, url)
    assert not problems, "\n".join(problems)


# -- the keyboard alone ----------------------------------------------------------------

TAB, ENTER = "\ue004", "\ue007"


def press(web: support.WebDriver, key: str) -> None:
    web.command("POST", "/actions", {"actions": [{"type": "key", "id": "keyboard", "actions": [
        {"type": "keyDown", "value": key}, {"type": "keyUp", "value": key}]}]})


FOCUSED = """const e = document.activeElement, s = getComputedStyle(e);
return {id: e.id, tag: e.tagName, text: (e.innerText || '').trim(), href: e.getAttribute('href'),
        outline: s.outlineStyle !== 'none' && parseFloat(s.outlineWidth) >= 2};"""


def tab_through(web: support.WebDriver, limit: int = 40) -> list[dict]:
    """Tab from the top of the page until focus comes round again; what was focused, in order."""
    seen: list[dict] = []
    web.run("document.activeElement && document.activeElement.blur(); window.scrollTo(0, 0);")
    for _ in range(limit):
        press(web, TAB)
        now = web.run(FOCUSED)
        if now["tag"] == "BODY" or (seen and now == seen[0]):
            break
        seen.append(now)
    return seen


def tab_through_page(web: support.WebDriver, service: Running, url: str) -> list[dict]:
    """alice's page ``url`` on a phone, tabbed through from the top."""
    as_user(web, service, "alice")
    web.resize(360, 800)
    web.open(url)
    return tab_through(web)


@pytest.mark.browser
def test_upload_page_works_with_the_keyboard(service: Running, browser: support.WebDriver,
                                             graded: int) -> None:
    stops = tab_through_page(browser, service, f"{service.url}/assignments/hull")
    assert stops[0]["href"] == "#main" and "Skip" in stops[0]["text"], stops[:2]
    ids = [s["id"] for s in stops]
    assert "notebook" in ids and "submit" in ids and "download" in ids, ids
    assert all(s["outline"] for s in stops), [s for s in stops if not s["outline"]]
    browser.open(f"{service.url}/assignments/hull")  # the skip link moves focus into the page
    press(browser, TAB)
    press(browser, ENTER)
    assert browser.run("return document.activeElement.id") == "main"


@pytest.mark.browser
def test_feedback_page_works_with_the_keyboard(service: Running, browser: support.WebDriver,
                                               graded: int) -> None:
    stops = tab_through_page(browser, service, f"{service.url}/submissions/{graded}/feedback")
    assert stops and stops[0]["href"] == f"/submissions/{graded}", stops
    assert all(s["outline"] for s in stops), stops
    browser.open(f"{service.url}/submissions/{graded}/feedback")
    press(browser, TAB)
    press(browser, ENTER)
    browser.wait_for(f"return location.pathname === '/submissions/{graded}'", timeout=60)


# -- the rough edges -----------------------------------------------------------------------

def test_deadline_words() -> None:
    from autograder.service.pages_student import deadline_words

    now = dt.datetime(2026, 12, 3, 17, 0)
    assert deadline_words(now - dt.timedelta(hours=2, minutes=5), now) == "passed 2 hours ago"
    assert deadline_words(now + dt.timedelta(days=3, hours=1), now) == "in 3 days"
    assert deadline_words(now + dt.timedelta(minutes=1), now) == "in 1 minute"
    assert deadline_words(now, now) == "passed less than a minute ago"


@pytest.mark.browser
def test_attempts_are_numbered_per_student_and_the_deadline_reads_well(
        service: Running, browser: support.WebDriver, graded: int) -> None:
    with httpx.Client(timeout=60) as client:  # another assignment's upload in between
        support.upload(client, service.url, service.tokens["alice"], "broken", SOLUTION)
        second = support.upload(client, service.url, service.tokens["alice"], "hull", SOLUTION).json()
    with service.engine.connect() as db:
        mine = db.execute(text("SELECT id FROM submissions WHERE user_id = 'alice' AND "
                               "assignment = 'hull' ORDER BY id")).scalars().all()
    assert mine[-1] == second["id"] and mine[-1] != len(mine)  # the database id is not the number
    as_user(browser, service, "alice")
    browser.open(f"{service.url}/submissions/{second['id']}")
    assert browser.text("h1") == f"Convex hull: attempt {len(mine)}"
    browser.open(f"{service.url}/assignments/hull")
    numbers = browser.run("return [...document.querySelectorAll('#history tbody tr td:first-child')]"
                          ".map(td => td.innerText)")
    assert numbers == [f"attempt {n}" for n in range(len(mine), 0, -1)]
    body = browser.run("return document.body.innerText")
    assert re.search(r"Deadline \d{4}-\d\d-\d\d \d\d:\d\d UTC \(passed \d+ hours? ago\)", body), body
    assert "left)" not in body
    as_user(browser, service, "bob")  # bob's extension runs for 30 days
    browser.open(f"{service.url}/assignments/hull")
    assert re.search(r"UTC \(in (29|30) days\)", browser.run("return document.body.innerText"))


@pytest.mark.browser
def test_regrade_says_what_it_queued(service: Running, browser: support.WebDriver,
                                     graded: int) -> None:
    as_user(browser, service, "prof")
    browser.open(f"{service.url}/instructor")
    assert browser.run("return document.getElementById('regrade-status')") is None
    browser.click("section#hull button.regrade")
    browser.wait_for("return location.search.includes('regrade=')", timeout=60)
    status = browser.text("#regrade-status")
    assert re.fullmatch(r"\d+ submission\(s\) of Convex hull queued for regrading; .*", status), status
    assert int(status.split()[0]) >= 1
    assert browser.run("return document.getElementById('regrade-status').getAttribute('role')") == "status"


def test_summary_has_a_table_of_students_with_links_and_ways_back(service: Running,
                                                                  graded: int) -> None:
    prof = {"Authorization": f"Bearer {service.tokens['prof']}"}
    with httpx.Client(base_url=service.url, timeout=60, headers=prof) as client:
        page = client.get("/instructor/hull/summary/").text
        table = re.search(r'<table id="students">.*?</table>', page, re.S)
        assert table, "no per-student table"
        assert '<a href="alice/feedback.html">alice</a>' in table.group(0)
        assert '<a href="/instructor">Back to the class</a>' in page
        # the link works from where the summary is served
        linked = client.get("/instructor/hull/summary/alice/feedback.html")
        assert linked.status_code == 200 and '<a href="../">Back to the class summary</a>' in linked.text
    mine = {"Authorization": f"Bearer {service.tokens['alice']}"}
    feedback = httpx.get(f"{service.url}/submissions/{graded}/feedback", headers=mine).text
    assert re.search(rf'<a href="/submissions/{graded}">Back to attempt \d+</a>', feedback)


def _solution_lines(notebook: dict) -> set[str]:
    """Lines inside the instructor's ### BEGIN/END SOLUTION regions (long enough to be telling)."""
    lines, inside = set(), False
    for cell in notebook["cells"]:
        for line in "".join(cell["source"]).splitlines():
            if "BEGIN SOLUTION" in line:
                inside = True
            elif "END SOLUTION" in line:
                inside = False
            elif inside and len(line.strip()) > 20:
                lines.add(line.strip())
    return lines


def test_the_released_notebook_is_downloaded_without_solutions_or_hidden_checks(
        service: Running) -> None:
    instructor = json.loads((support.ROOT / "assignments/hull/hull.ipynb").read_text())
    solution = _solution_lines(instructor)
    hidden = {line.strip() for path in (support.ROOT / "assignments/hull/checks/hidden").glob("*.py")
              for line in path.read_text().splitlines() if len(line.strip()) > 30}
    assert solution and hidden
    with httpx.Client(base_url=service.url, timeout=600) as client:
        assert client.get("/assignments/hull/notebook", follow_redirects=False).status_code in (303, 401)
        answer = client.get("/assignments/hull/notebook",
                            headers={"Authorization": f"Bearer {service.tokens['alice']}"})
    assert answer.status_code == 200, answer.text
    assert 'filename="hull.ipynb"' in answer.headers["content-disposition"]
    released = json.loads(answer.content)
    text_ = answer.text
    assert "BEGIN SOLUTION" not in text_ and "NotImplementedError" in text_
    assert not {line for line in solution if line in text_}
    assert not {line for line in hidden if line in text_}
    assert len(released["cells"]) > 3


def test_the_notebook_of_an_assignment_not_yet_open_is_not_given_to_students(
        service: Running) -> None:
    with httpx.Client(base_url=service.url, timeout=600) as client:
        early = client.get("/assignments/later/notebook",
                           headers={"Authorization": f"Bearer {service.tokens['alice']}"})
        assert early.status_code == 403 and "opens 2099-01-01 00:00 UTC" in early.text
        staff = client.get("/assignments/later/notebook",
                           headers={"Authorization": f"Bearer {service.tokens['prof']}"})
        assert staff.status_code == 200 and "BEGIN SOLUTION" not in staff.text


# -- the Canvas CSV's ID column -------------------------------------------------------------

def test_canvas_csv_fills_id_from_the_roster(tmp_path: Path) -> None:
    from autograder.errors import UsageError
    from autograder.service import auth, db, gradebook
    from autograder.service.course import AssignmentPolicy
    from autograder.service.standing import standing

    roster = tmp_path / "roster.csv"
    roster.write_text("id,name,email,canvas_id\nalice,Alice,a@x.edu,104321\nbob,Bob,b@x.edu,\n")
    engine = db.make_engine(f"sqlite:///{tmp_path / 'db.sqlite3'}")
    db.upgrade(engine)  # the migrations, 0005_pages among them
    factory = db.sessions(engine)
    with factory.begin() as session:
        auth.import_roster(session, auth.read_roster(roster))
    policy = AssignmentPolicy("hull", "hull", "Convex hull", dt.datetime(2020, 1, 1),
                              dt.datetime(2020, 2, 1))
    with factory() as session:
        rows = [(user, standing(session, policy, user.id))
                for user in session.scalars(db_select_users()).all()]
        canvas = list(csv.reader(io.StringIO(gradebook.canvas_csv(policy, rows))))
    engine.dispose()
    assert canvas[0][:3] == ["Student", "ID", "SIS User ID"]
    assert {row[2]: row[1] for row in canvas[2:]} == {"alice": "104321", "bob": ""}
    roster.write_text("id,name,email,canvas_id\nalice,Alice,a@x.edu,alice@canvas\n")
    with pytest.raises(UsageError, match="line 2: canvas_id is Canvas's numeric user id"):
        auth.read_roster(roster)


def db_select_users():
    from sqlalchemy import select

    from autograder.service.models import User

    return select(User).order_by(User.id)
