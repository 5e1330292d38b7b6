"""The student and instructor flows through a real server, in headless Chromium and over HTTP."""

from __future__ import annotations

import csv
import io
import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
import zipfile

import httpx
import pytest
import svc_support as support
from conftest import Running
from sqlalchemy import text

SOLUTION = (support.HULL_EXAMPLES / "solution.ipynb").read_bytes()
CLOCKWISE = (support.HULL_EXAMPLES / "wrong-clockwise.ipynb").read_bytes()


def sign_in(web: support.WebDriver, url: str, token: str) -> None:
    web.open(f"{url}/login")
    web.type("#token", token)
    web.click("#sign-in")
    web.wait_for("return !location.pathname.startsWith('/login')", timeout=60)


def cookie_client(url: str, token: str) -> tuple[httpx.Client, str]:
    """An HTTP client signed in through the login form, and the page's CSRF token."""
    client = httpx.Client(base_url=url, timeout=60)
    page = client.get("/login").text
    nonce = re.search(r'name="csrf" value="([^"]+)"', page).group(1)
    answer = client.post("/login", data={"csrf": nonce, "token": token, "next": "/assignments"})
    assert answer.status_code == 303, answer.text
    page = client.get("/assignments").text
    return client, re.search(r'name="csrf" value="([^"]+)"', page).group(1)


def status_of(web: support.WebDriver) -> str:
    return web.run("return document.getElementById('status').textContent")


@pytest.mark.browser
def test_student_uploads_in_the_browser_and_reads_feedback(service: Running,
                                                           browser: support.WebDriver,
                                                           tmp_path) -> None:
    sign_in(browser, service.url, service.tokens["bob"])
    browser.open(f"{service.url}/assignments")
    row = browser.text("tr[data-assignment=hull]")
    assert "Convex hull" in row and " 0 " in f" {row} "
    browser.open(f"{service.url}/assignments/hull")
    notebook = tmp_path / "hull.ipynb"
    notebook.write_bytes(SOLUTION)
    browser.type("#notebook", str(notebook))
    browser.click("#submit")
    browser.wait_for("return location.pathname.startsWith('/submissions/')", timeout=60)
    sub_id = int(browser.url.rsplit("/", 1)[1])
    browser.run("window.notReloaded = true")
    assert status_of(browser) in ("queued", "running", "graded")
    assert browser.wait_for("return document.getElementById('status').textContent === 'graded'")
    assert browser.run("return window.notReloaded === true"), "the page reloaded instead of updating"
    view = support.wait_graded(httpx.Client(), service.url, service.tokens["bob"], sub_id)
    assert view["score"] == view["max_score"] > 0
    assert browser.text("#score") == f"Score: {view['score']:g} / {view['max_score']:g}"
    browser.click("#feedback-link")
    browser.wait_for("return location.pathname.endsWith('/feedback')", timeout=60)
    # the feedback page runs in an opaque origin (CSP sandbox): it cannot reach the service
    assert browser.run("return window.origin") == "null"
    assert browser.run("try { return document.cookie, 'readable' } catch (e) { return 'blocked' }"
                       ) == "blocked"
    assert f"{view['score']:g}" in browser.run("return document.body.innerText")
    browser.open(f"{service.url}/assignments")
    row = browser.text("tr[data-assignment=hull]")
    assert f"{view['score']:g} / {view['max_score']:g}" in row


@pytest.mark.browser
def test_late_upload_shows_the_penalty(service: Running, browser: support.WebDriver,
                                       tmp_path) -> None:
    sign_in(browser, service.url, service.tokens["carol"])  # carol has no extension: 1 day late
    browser.open(f"{service.url}/assignments/hull")
    notebook = tmp_path / "hull.ipynb"
    notebook.write_bytes(CLOCKWISE)
    browser.type("#notebook", str(notebook))
    browser.click("#submit")
    browser.wait_for("return location.pathname.startsWith('/submissions/')", timeout=60)
    assert "1 day(s) late: −10%" in browser.run("return document.body.innerText")
    assert browser.wait_for("return document.getElementById('status').textContent === 'graded'")
    sub_id = int(browser.url.rsplit("/", 1)[1])
    view = support.wait_graded(httpx.Client(), service.url, service.tokens["carol"], sub_id)
    assert view["late_days"] == 1 and view["penalty"] == pytest.approx(0.1)
    assert view["score"] == pytest.approx(round(view["raw_score"] * 0.9, 6))
    assert "before the late penalty" in browser.text("#score")


@pytest.mark.browser
def test_instructor_watches_regrades_and_exports(service: Running, browser: support.WebDriver) -> None:
    with httpx.Client(timeout=60) as client:
        first = support.upload(client, service.url, service.tokens["dave"], "hull", CLOCKWISE).json()
        graded = support.wait_graded(client, service.url, service.tokens["dave"], first["id"])
    assert graded["status"] == "graded"
    sign_in(browser, service.url, service.tokens["prof"])
    browser.open(f"{service.url}/instructor")
    assert f"{graded['score']:g} / {graded['max_score']:g}" in browser.text(
        "section#hull tr[data-student=dave]")
    browser.open(f"{service.url}/instructor/hull/summary/")
    assert browser.run("return window.origin") == "null"  # student text inside: sandboxed
    body = browser.run("return document.body.innerText")
    with service.engine.connect() as db:  # one counted attempt per student with a graded one
        students = db.execute(text("SELECT count(DISTINCT user_id) FROM submissions "
                                   "WHERE assignment = 'hull' AND status = 'graded'")).scalar_one()
    assert f"{students} submission(s)" in body
    # regrade everything: old scores stay visible until each new one is in
    browser.open(f"{service.url}/instructor")
    with service.engine.connect() as db:
        before = db.execute(text("SELECT count(*) FROM gradings")).scalar_one()
        graded_ids = db.execute(text("SELECT id FROM submissions WHERE status = 'graded' "
                                     "AND assignment = 'hull'")).scalars().all()
    browser.click("section#hull button.regrade")
    browser.wait_for("return location.search.includes('regrade=')", timeout=60)
    with httpx.Client(timeout=60) as client:
        view = client.get(f"{service.url}/api/submissions/{first['id']}",
                          headers={"Authorization": f"Bearer {service.tokens['dave']}"}).json()
        assert view["status"] == "graded" and view["score"] == graded["score"]
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline:
            with service.engine.connect() as db:
                waiting = db.execute(text("SELECT count(*) FROM jobs WHERE state IN ('queued', 'running')")).scalar_one()
            if not waiting:
                break
            time.sleep(0.5)
        with service.engine.connect() as db:
            after = db.execute(text("SELECT count(*) FROM gradings")).scalar_one()
        assert after >= before + len(graded_ids)
        prof = {"Authorization": f"Bearer {service.tokens['prof']}"}
        grades = list(csv.DictReader(io.StringIO(
            client.get(f"{service.url}/instructor/hull/export/grades.csv", headers=prof).text)))
        by_id = {row["id"]: row for row in grades}
        assert {"alice", "bob", "carol", "dave", "eve"} <= set(by_id)  # roster ids...
        assert not {"prof", "tess"} & set(by_id)  # ...of students only
        assert float(by_id["dave"]["score"]) == graded["score"]
        if by_id["carol"]["score"]:
            assert by_id["carol"]["late_days"] == "1" and by_id["carol"]["penalty"] == "0.1"
        canvas = list(csv.reader(io.StringIO(
            client.get(f"{service.url}/instructor/hull/export/canvas.csv", headers=prof).text)))
        assert canvas[0][:5] == ["Student", "ID", "SIS User ID", "SIS Login ID", "Section"]
        assert canvas[1][0] == "Points Possible"
        assert any(r[2] == "dave" and float(r[5]) == graded["score"] for r in canvas[2:])
        junit = ET.fromstring(client.get(f"{service.url}/instructor/hull/export/junit.xml",
                                         headers=prof).content)
        assert "dave" in {s.get("name") for s in junit.iter("testsuite")}
        archive = zipfile.ZipFile(io.BytesIO(client.get(
            f"{service.url}/instructor/hull/export/gradescope.zip", headers=prof).content))
        assert "dave/results.json" in archive.namelist()


def test_extension_revoked_then_late_upload(service: Running) -> None:
    """alice gets an extension, submits on time, loses it, submits again: 1 day late, 10% off."""
    prof, csrf = cookie_client(service.url, service.tokens["prof"])
    try:
        later = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(time.time() + 7 * 86400))
        answer = prof.post("/instructor/extensions", data={
            "csrf": csrf, "student": "alice", "assignment": "hull", "deadline": later})
        assert answer.status_code == 303, answer.text
        with httpx.Client(timeout=60) as client:
            on_time = support.upload(client, service.url, service.tokens["alice"], "hull", SOLUTION).json()
            assert on_time["late_days"] == 0
            answer = prof.post("/instructor/extensions", data={
                "csrf": csrf, "student": "alice", "assignment": "hull", "deadline": ""})
            assert answer.status_code == 303
            late = support.upload(client, service.url, service.tokens["alice"], "hull", SOLUTION).json()
            assert late["late_days"] == 1 and late["penalty"] == pytest.approx(0.1)
            view = support.wait_graded(client, service.url, service.tokens["alice"], late["id"])
            assert view["score"] == pytest.approx(0.9 * view["raw_score"])
        page = prof.get("/instructor/students/alice").text
        assert "1 d, −10%" in page
    finally:
        prof.close()


def test_submit_command_prints_score_and_link(service: Running, tmp_path) -> None:
    notebook = tmp_path / "hull.ipynb"
    notebook.write_bytes(CLOCKWISE)
    run = subprocess.run([sys.executable, "-m", "autograder", "submit", str(notebook),
                          "--server", service.url, "--token", service.tokens["bob"]],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stdout + run.stderr
    assert re.search(r"^Score: [\d.]+/[\d.]+$", run.stdout, re.M), run.stdout
    link = re.search(r"^Feedback: (\S+)$", run.stdout, re.M).group(1)
    assert link.startswith(f"{service.url}/submissions/") and link.endswith("/feedback")
    page = httpx.get(link, headers={"Authorization": f"Bearer {service.tokens['bob']}"})
    assert page.status_code == 200 and "sandbox" in page.headers["content-security-policy"]


def test_engine_failure_is_retried_shown_to_staff_and_never_a_zero(service: Running) -> None:
    """A check that cannot be collected: retried, then "error" for the instructor, no score;
    once the check is fixed, "regrade" grades it."""
    with httpx.Client(timeout=60) as client:
        sub = support.upload(client, service.url, service.tokens["dave"], "broken", CLOCKWISE).json()
        view = support.wait_graded(client, service.url, service.tokens["dave"], sub["id"])
        assert view["status"] == "error" and view["score"] is None and view["raw_score"] is None
        assert "not a zero" in view["message"]
        page = client.get(f"{service.url}/assignments/broken",
                          headers={"Authorization": f"Bearer {service.tokens['dave']}"}).text
        assert "not graded (not a zero)" in page
        with service.engine.connect() as db:
            job = db.execute(text("SELECT state, tries, error FROM jobs WHERE submission_id = :s"),
                             {"s": sub["id"]}).one()
        assert job.state == "failed" and job.tries == 3 and job.error
        staff = client.get(f"{service.url}/instructor",
                           headers={"Authorization": f"Bearer {service.tokens['prof']}"}).text
        assert "Needs a person" in staff
        failed = staff.split('id="failed"')[1].split("</table>")[0]
        assert "dave" in failed and "broken" in failed and "failed" in failed
        grades = client.get(f"{service.url}/instructor/broken/export/grades.csv",
                            headers={"Authorization": f"Bearer {service.tokens['prof']}"}).text
        dave = next(r for r in csv.DictReader(io.StringIO(grades)) if r["id"] == "dave")
        assert dave["score"] == "" and dave["outcome"] != "graded"
        # fix the check (the grading processes notice the changed checks) and regrade
        folder = service.server.course.parent / "broken-hull" / "checks" / "hidden"
        for saved in folder.glob("test_*.ok"):
            saved.rename(saved.with_suffix(".py"))
        answer = client.post(f"{service.url}/instructor/broken/regrade",
                             headers={"Authorization": f"Bearer {service.tokens['prof']}",
                                      "Accept": "application/json"})
        with service.engine.connect() as db:  # other tests of the session may upload to it too
            broken = db.execute(text("SELECT count(*) FROM submissions "
                                     "WHERE assignment = 'broken'")).scalar_one()
        assert answer.json() == {"queued": broken} and broken >= 1
        view = support.wait_graded(client, service.url, service.tokens["dave"], sub["id"])
        deadline = time.monotonic() + 600
        while view["status"] != "graded" and time.monotonic() < deadline:
            time.sleep(0.5)
            view = support.wait_graded(client, service.url, service.tokens["dave"], sub["id"])
        assert view["status"] == "graded" and view["score"] > 0
