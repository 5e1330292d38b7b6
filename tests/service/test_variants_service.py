"""Per-student variants through the service: each student downloads their own problem,
both right answers get full marks, and a student off the roster of variants is told so.

The assignment is the test-written ``scaled`` of ``tests/autograder/test_variants.py``:
``scaled(x)`` multiplies by the student's parameter ``a``, drawn from the course secret.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterator

import httpx
import nbformat
import pytest
import svc_support as support

from autograder.engine.assignment import load_assignment
from tests.autograder.test_variants import SOLUTION, write_scaled

SECRET = "the service test's course secret"


@pytest.fixture(scope="module")
def scaled(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[support.Server, Path]]:
    folder = tmp_path_factory.mktemp("variants")
    source = write_scaled(folder)
    body = """
[course]
name = "Variants course"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "scaled"
assignment = "./scaled"
opens = 2020-01-01T00:00:00Z
deadline = 2099-01-01T00:00:00Z
"""
    course = support.write_course(folder, body=body, roster=[
        ("ada", "Ada", "ada@uni", "student"), ("bob", "Bob", "bob@uni", "student"),
        ("carl", "Carl", "carl@uni", "student")])
    before = os.environ.get("NUMGRADE_VARIANT_SECRET")
    os.environ["NUMGRADE_VARIANT_SECRET"] = SECRET  # the server's and this test's
    server = support.Server(course, f"sqlite:///{folder / 'db.sqlite3'}", jobs=1)
    server.start()
    try:
        yield server, source
    finally:
        server.stop()
        if before is None:
            os.environ.pop("NUMGRADE_VARIANT_SECRET", None)
        else:
            os.environ["NUMGRADE_VARIANT_SECRET"] = before


def _download(client: httpx.Client, server: support.Server, who: str) -> httpx.Response:
    return client.get(f"{server.url}/assignments/scaled/notebook",
                      headers={"Authorization": f"Bearer {server.tokens()[who]}"})


def test_each_student_gets_their_own_problem_and_both_right_answers_score_full(
        scaled: tuple[support.Server, Path]) -> None:
    server, source = scaled
    spec = load_assignment(source).variants
    assert spec is not None
    values = {s: spec.draw("scaled", s)["a"] for s in ("ada", "bob")}
    assert values["ada"] != values["bob"]
    with httpx.Client(timeout=300) as client:
        for student, value in values.items():
            answer = _download(client, server, student)
            assert answer.status_code == 200, answer.text
            book = nbformat.reads(answer.text, as_version=4)
            params = [c for c in book.cells if "variant" in c.metadata.get("tags", [])]
            assert len(params) == 1 and f"a = {value}" in params[0].source
            assert "a * x" not in answer.text  # the solution was cut out
            book.cells[1].source = SOLUTION
            sub = support.upload(client, server.url, server.tokens()[student], "scaled",
                                 json.dumps(book).encode(), name="scaled.ipynb")
            assert sub.status_code == 201, sub.text
            view = support.wait_graded(client, server.url, server.tokens()[student],
                                       sub.json()["id"])
            assert view["status"] == "graded" and view["score"] == view["max_score"] > 0, view


def test_a_student_off_the_roster_of_variants_is_told_so(
        scaled: tuple[support.Server, Path]) -> None:
    server, _ = scaled
    with httpx.Client(timeout=300) as client:
        answer = _download(client, server, "carl")
    assert answer.status_code == 403
    assert "not on its roster of variants" in answer.text
