"""The feedback page as a person sees it, in headless Chromium opened from disk (file://).

Chromium is driven through chromedriver's W3C WebDriver HTTP interface with
the standard library only (no Selenium, nothing downloaded): the Debian
packages ``chromium`` and ``chromium-driver`` are all it needs. The test skips
only when those are not installed (``.ci/run`` installs them, so CI runs it).
The screenshots are kept under pytest's temporary folder; their paths are printed
(run with ``-s`` to see them).
"""

from __future__ import annotations

import io
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from autograder.results.feedback import write_feedback
from autograder.results.model import Attachment, CellError, CheckResult, SubmissionResult
from tests.support.webdriver import CHROMEDRIVER, CHROMIUM, WebDriver, start_chromedriver

pytestmark = pytest.mark.browser

@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[WebDriver]:
    if not (CHROMIUM and CHROMEDRIVER):
        pytest.skip("headless Chromium is not installed: apt-get install chromium chromium-driver "
                    "(.ci/run does this in CI)")
    driver, web = start_chromedriver(tmp_path_factory.mktemp("chromedriver"))
    try:
        try:
            yield web
        finally:
            web.quit()
    finally:
        driver.terminate()
        try:
            driver.wait(timeout=10)
        except subprocess.TimeoutExpired:
            driver.kill()


def _car_png(jitter: float, colour: str) -> bytes:
    """A car drawn with the reference's strokes (``jitter`` moves the student's a little)."""
    from matplotlib.figure import Figure

    from reference import car, plot_car

    strokes = [s + jitter * np.sin(np.arange(s.size).reshape(s.shape)) for s in car()]
    fig = Figure(figsize=(4, 2), dpi=60)
    ax = fig.add_subplot()
    plot_car(ax, strokes, num=60)
    for line in ax.get_lines():
        line.set_color(colour)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


HOSTILE = "<script>document.title='pwned'</script><img src=x onerror=alert(1)>"


@pytest.fixture(scope="module")
def page(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, SubmissionResult]:
    folder = tmp_path_factory.mktemp("results") / "alice"
    images = folder / "images"
    images.mkdir(parents=True)
    (images / "student-car.png").write_bytes(_car_png(0.08, "tab:blue"))
    (images / "reference-car.png").write_bytes(_car_png(0.0, "black"))
    (images / "unseen.png").write_bytes(_car_png(0.0, "black"))
    tests = (
        CheckResult("spline_coefficients_small[worked-example]", 1, 1, "", hidden=False,
                    dataset="worked-example"),
        CheckResult("draw_car", 1.5, 3, "Your car's rear wheel is 4% off the reference.",
                    hidden=False, kind="partial",
                    attachments=(Attachment("your car", "images/student-car.png"),
                                 Attachment("the reference car", "images/reference-car.png"))),
        CheckResult("spline_eval_small", 0, 1, HOSTILE, hidden=False, kind="wrong"),
        CheckResult("draw_car_unseen[unseen-car]", 0, 2, "Parts of the car are missing.", hidden=True,
                    kind="wrong", dataset="unseen-car",
                    attachments=(Attachment("unseen car", "images/unseen.png"),)),
    )
    result = SubmissionResult(
        id="alice", source="alice.ipynb", assignment="spline_car", key="k", sha256="ab" * 32,
        outcome="graded", output="Your notebook's 5 code cell(s) ran in 2.4 s.", tests=tests,
        execution_time=3.2, seed=7, stdout="x = 1\n" * 3000 + HOSTILE,
        cell_errors=(CellError(2, "ZeroDivisionError", "division by zero",
                               "Traceback (most recent call last):\n  Cell In[3], line 1\n"
                               "ZeroDivisionError: division by zero"),))
    write_feedback(folder, result, title="Draw a car with a cubic spline")
    return folder / "feedback.html", result


def test_feedback_page_shows_score_checks_and_both_cars(
        browser: WebDriver, page: tuple[Path, SubmissionResult], tmp_path: Path) -> None:
    path, result = page
    browser.resize(1000, 900)
    browser.open(path.resolve().as_uri())
    seen = browser.run("""
        const imgs = [...document.images].map(i => ({alt: i.alt, complete: i.complete,
            w: i.naturalWidth, h: i.naturalHeight, src: i.src.slice(0, 22)}));
        return {title: document.title, text: document.body.innerText, imgs: imgs,
                score: document.getElementById('score').innerText,
                scripts: document.scripts.length, height: document.documentElement.scrollHeight};
    """)
    assert seen["score"] == "2.5 / 7" == f"{result.score:g} / {result.max_score:g}"
    assert seen["title"] == "Draw a car with a cubic spline: feedback for alice"
    for check in result.tests:
        assert check.name in seen["text"]
    assert "Your car's rear wheel is 4% off the reference." in seen["text"]
    cars = {i["alt"].split(":")[0]: i for i in seen["imgs"]}
    assert set(cars) == {"your car", "the reference car"}, "hidden checks must not show pictures"
    # the text alternative says what the check found, not just "figure"
    assert all("rear wheel is 4% off" in i["alt"] for i in seen["imgs"])
    for image in cars.values():
        assert image["complete"] and image["w"] > 0 and image["h"] > 0, image
        assert image["src"].startswith("data:image/png;base64")
    assert seen["scripts"] == 0 and HOSTILE in seen["text"], "untrusted text must stay text"
    assert "ZeroDivisionError" in seen["text"] and "line(s) not shown" in seen["text"]
    browser.resize(1000, min(int(seen["height"]) + 40, 4000))
    shot = browser.screenshot(tmp_path / "feedback.png")
    print(f"\nfeedback page screenshot: {shot}")
    assert shot.stat().st_size > 10_000


def test_feedback_page_fits_a_phone_and_has_print_styles(
        browser: WebDriver, page: tuple[Path, SubmissionResult], tmp_path: Path) -> None:
    path, _ = page
    browser.resize(390, 844)
    browser.open(path.resolve().as_uri())
    seen = browser.run("""
        const media = [...document.styleSheets].flatMap(s => [...s.cssRules])
            .filter(r => r.media).map(r => r.media.mediaText);
        const widest = Math.max(...[...document.images].map(i => i.getBoundingClientRect().right));
        return {scroll: document.documentElement.scrollWidth, inner: window.innerWidth,
                widest: widest, media: media};
    """)
    assert seen["scroll"] <= seen["inner"], "the page must not scroll sideways on a phone"
    assert seen["widest"] <= seen["inner"]
    assert any("print" in m for m in seen["media"])
    shot = browser.screenshot(tmp_path / "feedback-phone.png")
    print(f"\nfeedback page on a phone: {shot}")
