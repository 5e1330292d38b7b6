"""Manual grading through a real server: rubric, release, regrade request, override, exports.

The assignment is a small nbgrader one written here: ``double`` checked by a test
cell (1 point) and a written answer ``explain`` graded by a person (3 points).
The student's answer holds a formula and two attacks on the staff page: a raw
``<script>`` and one smuggled through LaTeX (``\\text{<script>...}``).
"""

from __future__ import annotations

import csv
import io
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Callable

import httpx
import nbformat
import pytest
import svc_support as support
from conftest import CLASS
from test_flows import cookie_client, sign_in

pytestmark = pytest.mark.timeout(1500)

ANSWER = ("The error halves each step, so the order is $p = \\frac{\\log e_{k+1}}{\\log e_k}$.\n\n"
          "<script>document.title='pwned-raw'</script>\n\n"
          "$\\text{<script>document.title='pwned-tex'</script>}$\n")


def _cells(answer: str) -> list[nbformat.NotebookNode]:
    meta = {"locked": False, "schema_version": 3}
    return [
        nbformat.v4.new_code_cell("### BEGIN SOLUTION\ndef double(x):\n    return 2 * x\n### END SOLUTION",
                                  metadata={"nbgrader": {**meta, "grade_id": "double", "solution": True,
                                                         "grade": False}}),
        nbformat.v4.new_code_cell("assert double(2) == 4",
                                  metadata={"nbgrader": {**meta, "grade_id": "test_double",
                                                         "solution": False, "grade": True,
                                                         "points": 1, "locked": True}}),
        nbformat.v4.new_markdown_cell(answer, metadata={"nbgrader": {
            **meta, "grade_id": "explain", "solution": True, "grade": True, "points": 3}}),
    ]


def write_assignment(folder: Path) -> Path:
    folder.mkdir(parents=True)
    (folder / "assignment.toml").write_text(
        '[assignment]\nname = "essay"\ntitle = "Essay"\nformat = "nbgrader"\nnotebook = "essay.ipynb"\n')
    nbformat.write(nbformat.v4.new_notebook(cells=_cells("YOUR ANSWER HERE")), folder / "essay.ipynb")
    return folder


@pytest.fixture(scope="module")
def server(database: Callable[[str], str], tmp_path_factory: pytest.TempPathFactory
           ) -> Iterator[tuple[support.Server, dict[str, str]]]:
    folder = tmp_path_factory.mktemp("manual")
    write_assignment(folder / "essay")
    body = """
[course]
name = "Manual grading course"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "essay"
assignment = "./essay"
opens = 2020-01-01T00:00:00Z
deadline = 2099-01-01T00:00:00Z
"""
    running = support.Server(support.write_course(folder, body=body, roster=CLASS),
                             database("manual"), jobs=1)
    running.start()
    try:
        yield running, running.tokens()
    finally:
        running.stop()


def csrf_of(page: str) -> str:
    return re.search(r'name="csrf" value="([^"]+)"', page).group(1)


def grades(client: httpx.Client) -> dict[str, dict[str, str]]:
    text = client.get("/instructor/essay/export/grades.csv").text
    return {row["id"]: row for row in csv.DictReader(io.StringIO(text))}


@pytest.mark.browser
def test_a_ta_grades_releases_and_the_student_reads_asks_and_is_overridden(
        server: tuple[support.Server, dict[str, str]], browser: support.WebDriver,
        tmp_path: Path) -> None:
    srv, tokens = server
    notebook = nbformat.v4.new_notebook(cells=_cells(ANSWER))
    with httpx.Client(timeout=60) as plain:
        sent = support.upload(plain, srv.url, tokens["alice"], "essay",
                              nbformat.writes(notebook).encode(), name="essay.ipynb")
        assert sent.status_code == 201, sent.text
        sub_id = sent.json()["id"]
        view = support.wait_graded(plain, srv.url, tokens["alice"], sub_id)
    assert view["status"] == "graded" and view["score"] == 1 and view["max_score"] == 4, view

    # the TA grades in the browser: anonymous, the formula as MathML, no student script ran
    sign_in(browser, srv.url, tokens["tess"])
    browser.open(f"{srv.url}/instructor/essay/grading/explain")
    assert "Submission 1 of 1" in browser.text("#position")
    assert "Alice" not in browser.text("main") and "alice" not in browser.text("#answer")
    assert browser.run("return document.querySelectorAll('#answer math mfrac').length") == 1
    assert browser.run("return document.querySelectorAll('main script:not([src])').length") == 0
    assert "pwned" not in browser.run("return document.title")
    browser.type("#new-item input[name=text]", "Names the order of convergence")
    browser.type("#new-item input[name=points]", "2")
    browser.click("#new-item button")
    browser.wait_for("return document.querySelector('button.apply') !== null", timeout=60)
    browser.run("document.dispatchEvent(new KeyboardEvent('keydown', {key: '1'}))")
    browser.wait_for("return document.getElementById('points').textContent === '2'", timeout=60)
    browser.type("#comment", "Say why the error halves.")
    browser.click("#comment-form button")
    browser.wait_for("return document.getElementById('comment').value.includes('halves')", timeout=60)
    browser.resize(1100, 1200)
    browser.screenshot(tmp_path / "grading.png")
    if os.environ.get("NUMGRADE_SCREENSHOT"):  # where to keep the picture for a person to look at
        shutil.copy(tmp_path / "grading.png", os.environ["NUMGRADE_SCREENSHOT"])

    staff, staff_csrf = cookie_client(srv.url, tokens["tess"])
    student, student_csrf = cookie_client(srv.url, tokens["alice"])
    prof, prof_csrf = cookie_client(srv.url, tokens["prof"])
    try:
        _through_http(sub_id, staff, staff_csrf, student, student_csrf, prof, prof_csrf)
    finally:
        for client in (staff, student, prof):
            client.close()


def _through_http(sub_id: int, staff: httpx.Client, staff_csrf: str, student: httpx.Client,
                  student_csrf: str, prof: httpx.Client, prof_csrf: str) -> None:
    if True:  # kept indented as one block: the steps follow each other on the same attempt
        home = staff.get("/instructor/essay/grading").text
        assert re.search(r'class="progress">1 / 1<', home), home
        # before release: the student sees neither the items nor the points
        page = student.get(f"/submissions/{sub_id}").text
        assert "Names the order" not in page and "halves." not in page
        assert student.get(f"/api/submissions/{sub_id}").json()["score"] == 1
        assert grades(staff)["alice"]["score"] == "1"

        # editing the item's points changes the answer it was applied to
        item = re.search(r'/grading/explain/items/(\d+)"', staff.get(
            "/instructor/essay/grading/explain?n=1").text).group(1)
        edited = staff.post(f"/instructor/essay/grading/explain/items/{item}",
                            data={"csrf": staff_csrf, "text": "Names the order of convergence",
                                  "points": "2.5", "n": "1"})
        assert edited.status_code == 303, edited.text
        assert 'id="points">2.5<' in staff.get("/instructor/essay/grading/explain?n=1").text

        released = staff.post("/instructor/essay/grading/release",
                              data={"csrf": staff_csrf, "question": "explain"})
        assert released.status_code == 303, released.text
        page = student.get(f"/submissions/{sub_id}").text
        assert "Names the order of convergence (+2.5)" in page and "Say why the error halves." in page
        assert student.get(f"/api/submissions/{sub_id}").json()["score"] == 3.5
        assert "graded by a person" in student.get(f"/submissions/{sub_id}/feedback").text
        row = grades(staff)["alice"]
        assert (row["raw_score"], row["score"]) == ("3.5", "3.5")
        canvas = staff.get("/instructor/essay/export/canvas.csv").text
        assert any(r[2] == "alice" and r[-1] == "3.5" for r in csv.reader(io.StringIO(canvas)))
        junit = staff.get("/instructor/essay/export/junit.xml").text
        assert re.search(r'name="explain"', junit)

        # the student asks for a regrade of the answer; staff answer in the same thread
        asked = student.post(f"/submissions/{sub_id}/regrade-requests",
                             data={"csrf": student_csrf, "check": "explain",
                                   "message": "I did say why, in the second sentence."})
        assert asked.status_code == 303, asked.text
        listing = staff.get("/instructor/regrade-requests").text
        request_id = re.search(rf'/instructor/submissions/{sub_id}#regrades', listing)
        assert request_id is not None, listing
        thread = re.search(r'action="/submissions/\d+/regrade-requests/(\d+)"',
                           staff.get(f"/instructor/submissions/{sub_id}").text).group(1)
        answered = staff.post(f"/submissions/{sub_id}/regrade-requests/{thread}",
                              data={"csrf": staff_csrf, "message": "Agreed: see the new score."})
        assert answered.status_code == 303, answered.text
        page = student.get(f"/submissions/{sub_id}").text
        assert "Agreed: see the new score." in page and 'data-status="answered"' in page

        # a TA may not override; the instructor does, with a reason the student reads
        refused = staff.post(f"/instructor/submissions/{sub_id}/override",
                             data={"csrf": staff_csrf, "check": "", "score": "4", "reason": "x"})
        assert refused.status_code == 403
        done = prof.post(f"/instructor/submissions/{sub_id}/override",
                         data={"csrf": prof_csrf, "check": "explain", "score": "3",
                               "reason": "The second sentence does explain it."})
        assert done.status_code == 303, done.text
        page = student.get(f"/submissions/{sub_id}").text
        assert "The second sentence does explain it." in page
        assert student.get(f"/api/submissions/{sub_id}").json()["score"] == 4
        row = grades(prof)["alice"]
        assert row["score"] == "4"
        summary = prof.get("/instructor/essay/summary/").text
        assert re.search(r'id="mean">100(\.0)?%<', summary), summary  # 4 of 4: the combined score

        # one attempt regraded: its score stays meanwhile and people's grading survives it
        again = prof.post(f"/instructor/submissions/{sub_id}/regrade", data={"csrf": prof_csrf})
        assert again.status_code == 303, again.text
        assert student.get(f"/api/submissions/{sub_id}").json()["score"] == 4
        for _ in range(1200):  # a generous bound: the test fails rather than hangs
            if 'a grading is waiting' not in prof.get(f"/instructor/submissions/{sub_id}").text:
                break
            time.sleep(0.5)
        view = student.get(f"/api/submissions/{sub_id}").json()
        assert view["status"] == "graded" and view["score"] == 4, view


def test_a_forged_or_foreign_grading_request_changes_nothing(
        server: tuple[support.Server, dict[str, str]]) -> None:
    srv, tokens = server
    student, csrf = cookie_client(srv.url, tokens["bob"])
    try:
        assert student.get("/instructor/essay/grading").status_code == 403
        assert student.post("/instructor/essay/grading/release",
                            data={"csrf": csrf, "question": ""}).status_code == 403
        # another student's attempt: the same 404 as one that does not exist
        assert student.post("/submissions/1/regrade-requests",
                            data={"csrf": csrf, "check": "", "message": "mine?"}).status_code == 404
    finally:
        student.close()
