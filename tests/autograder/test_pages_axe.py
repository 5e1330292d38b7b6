"""The feedback and class-summary pages a batch writes, checked with axe-core at WCAG 2.1 AA.

Opened from disk (file://) in headless Chromium at a phone's and a desktop's
width: no violation, no sideways scrolling, the car picture within the page,
every picture's text alternative saying what its check found, and the summary's
per-student table linking to each feedback page.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from autograder.results.feedback import write_feedback
from autograder.results.model import Attachment, CheckResult, SubmissionResult
from autograder.results.summary import write_summary
from tests.autograder import test_browser
from tests.autograder.test_browser import HOSTILE, _car_png
from tests.support import axe
from tests.support.webdriver import WebDriver

pytestmark = pytest.mark.browser

MESSAGE = "Your car's rear wheel is 4% off the reference at x = 3.2."


#: the feedback-page tests' headless Chromium (a module-scoped fixture)
browser = test_browser.browser


axe_js = axe.axe_js


def _result(folder: Path, sid: str, wheel: float) -> SubmissionResult:
    images = folder / sid / "images"
    images.mkdir(parents=True)
    # a wide picture: it must shrink to a phone's width, not push the page sideways
    (images / "car.png").write_bytes(_car_png(wheel, "tab:blue"))
    tests = (
        CheckResult("spline_coefficients_small[worked-example]", 1, 1, "", hidden=False),
        CheckResult("draw_car", 1.5, 3, MESSAGE, hidden=False, kind="partial",
                    attachments=(Attachment("your car", "images/car.png"),)),
        CheckResult("spline_eval_" + "very_long_name_" * 8, 0, 1, HOSTILE, hidden=False, kind="wrong"),
        CheckResult("draw_car_unseen[unseen-car]", 0, 2, "Parts are missing.", hidden=True,
                    kind="wrong"),
    )
    return SubmissionResult(id=sid, source=f"{sid}.ipynb", assignment="spline_car", key="k",
                            sha256="ab" * 32, outcome="graded", output="ran", tests=tests,
                            execution_time=1.0, seed=1, stdout="x" * 2000)


@pytest.fixture(scope="module")
def batch(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("batch")
    results = [_result(folder, sid, w) for sid, w in (("alice", 0.08), ("bob", 0.0))]
    for result in results:
        write_feedback(folder / result.id, result, title="Draw a car with a cubic spline")
    write_summary(folder, results, title="Draw a car with a cubic spline")
    return folder


def test_feedback_and_summary_pass_axe_and_fit_a_phone(browser: WebDriver, axe_js: str,
                                                       batch: Path) -> None:
    problems = []
    for page in (batch / "alice" / "feedback.html", batch / "summary.html"):
        problems += axe.page_problems(browser, axe_js, page.as_uri())
    assert not problems, "\n".join(problems)


def test_the_car_fits_and_says_what_the_check_found(browser: WebDriver, batch: Path) -> None:
    web = browser
    web.resize(360, 800)
    web.open((batch / "alice" / "feedback.html").as_uri())
    pictures = web.run("return [...document.images].map(i => ({alt: i.alt, "
                       "right: i.getBoundingClientRect().right}))")
    assert len(pictures) == 1
    assert pictures[0]["alt"] == f"your car: {MESSAGE}"
    assert pictures[0]["right"] <= web.run("return window.innerWidth")


def test_summary_lists_every_student_with_a_link(browser: WebDriver, batch: Path) -> None:
    web = browser
    web.open((batch / "summary.html").as_uri())
    rows = web.run("return [...document.querySelectorAll('#students tbody tr')].map(r => "
                   "({text: r.innerText, href: r.querySelector('a').getAttribute('href')}))")
    assert [r["href"] for r in rows] == ["alice/feedback.html", "bob/feedback.html"]
    assert all("2.5 / 7" in r["text"] and "1 / 4" in r["text"] for r in rows), rows
    web.click("#students a")
    web.wait_for("return location.pathname.endsWith('alice/feedback.html')", timeout=60)
