"""Every page of the service for everyone: axe-core at WCAG 2.1 AA, the keyboard alone, a phone.

A real server on loopback (the class course of ``conftest.py``), headless
Chromium over WebDriver, and the real axe-core script (``tests/support/axe.py``).
Then the rough edges: attempts numbered per student, the deadline's wording, a
confirmation after a regrade, the Canvas ID column, the released notebook.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import httpx
import pytest
import svc_support as support
from conftest import Running
from sqlalchemy import text
from test_flows import sign_in

from tests.support import axe

SOLUTION = (support.HULL_EXAMPLES / "solution.ipynb").read_bytes()


@pytest.fixture(scope="module")
def axe_js() -> str:
    script = axe.axe_script()
    if script is None:
        pytest.skip(axe.skip_reason())
    return script


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


def staff_pages(url: str) -> list[str]:
    return [f"{url}/instructor", f"{url}/instructor/students/alice"]


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
    for url in staff_pages(service.url):
        problems += axe.page_problems(browser, axe_js, url)
    assert not problems, "\n".join(problems)
