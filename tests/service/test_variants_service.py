"""Per-student variants through the service: each student downloads their own problem,
both right answers get full marks, and a student off the roster of variants is told so.

The assignments are the test-written ``scaled`` of ``tests/autograder/test_variants.py``
(``scaled(x)`` multiplies by the student's parameter ``a``, drawn from the course secret)
and the shipped ``hull`` (every student their own board of pins), where a copied hull
is recorded with its evidence.
"""

from __future__ import annotations

import contextlib
import html
import json
import os
from pathlib import Path
from typing import Iterator

import httpx
import nbformat
import numpy as np
import pytest
import svc_support as support

from autograder.engine.assignment import load_assignment
from reference import convex_hull
from tests.autograder.test_hull_variants import HULL, parameters, with_model_solution
from tests.autograder.test_variants import SOLUTION, write_scaled

SECRET = "the service test's course secret"


def course_body(title: str, name: str, assignment: str) -> str:
    """A course of one assignment ``name`` (the folder ``assignment``), open until 2099."""
    return f"""
[course]
name = "{title}"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "{name}"
assignment = "{assignment}"
opens = 2020-01-01T00:00:00Z
deadline = 2099-01-01T00:00:00Z
"""


@contextlib.contextmanager
def serving(folder: Path, body: str, students: tuple[str, ...]) -> Iterator[support.Server]:
    """A course server with the course secret in its environment (and this test's)."""
    course = support.write_course(folder, body=body, roster=[
        (s, s.title(), f"{s}@uni", "student") for s in students]
        + [("prof", "Prof", "prof@uni", "instructor")])
    before = os.environ.get("NUMGRADE_VARIANT_SECRET")
    os.environ["NUMGRADE_VARIANT_SECRET"] = SECRET  # the server's and this test's
    server = support.Server(course, f"sqlite:///{folder / 'db.sqlite3'}", jobs=1)
    server.start()
    try:
        yield server
    finally:
        server.stop()
        if before is None:
            os.environ.pop("NUMGRADE_VARIANT_SECRET", None)
        else:
            os.environ["NUMGRADE_VARIANT_SECRET"] = before


@pytest.fixture(scope="module")
def scaled(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[support.Server, Path]]:
    folder = tmp_path_factory.mktemp("variants")
    source = write_scaled(folder)
    body = course_body("Variants course", "scaled", "./scaled")
    with serving(folder, body, ("ada", "bob", "carl")) as server:
        yield server, source


def _download(client: httpx.Client, server: support.Server, who: str,
              name: str = "scaled") -> httpx.Response:
    return client.get(f"{server.url}/assignments/{name}/notebook",
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


@pytest.fixture(scope="module")
def hull(tmp_path_factory: pytest.TempPathFactory) -> Iterator[support.Server]:
    folder = tmp_path_factory.mktemp("hull-variants")
    body = course_body("Hull variants course", "hull", str(HULL))
    with serving(folder, body, ("alice", "bob", "carol")) as server:  # on hull's roster.csv
        yield server


def test_hull_boards_through_the_service_and_a_copied_hull_is_recorded(
        hull: support.Server) -> None:
    server = hull
    books, pins = {}, {}
    with httpx.Client(timeout=300) as client:
        for student in ("alice", "bob", "carol"):
            answer = _download(client, server, student, "hull")
            assert answer.status_code == 200, answer.text
            books[student] = Path(server.course.parent / f"{student}-hull.ipynb")
            books[student].write_text(answer.text)
            pins[student] = parameters(books[student])["pins"]
        assert pins["alice"] != pins["bob"] != pins["carol"]
        alices = [int(i) for i in convex_hull(np.array(pins["alice"]))]
        copied = ("_march = convex_hull\n\n\ndef convex_hull(points):\n"
                  f"    if len(points) == 31:\n        return {alices}\n    return _march(points)\n")
        views = {}
        for student in ("alice", "bob", "carol"):
            book = with_model_solution(books[student], copied if student == "carol" else "")
            sub = support.upload(client, server.url, server.tokens()[student], "hull",
                                 nbformat.writes(book).encode(), name="hull.ipynb")
            assert sub.status_code == 201, sub.text
            views[student] = support.wait_graded(client, server.url, server.tokens()[student],
                                                 sub.json()["id"])
    for student in ("alice", "bob"):
        assert views[student]["score"] == views[student]["max_score"] == 38, views[student]
    assert views["carol"]["score"] < views["carol"]["max_score"]
    found = [json.loads(p.read_text()) for p in
             (server.course.parent / "data").rglob("results.json")]
    stored = {r["extra_data"]["id"]: r for r in found}
    assert stored["alice"]["extra_data"]["variant"]["params"] == {"pins": pins["alice"]}
    notes = " ".join(stored["carol"]["extra_data"].get("notes", []))
    assert f"{alices} is the answer of alice's variant" in notes, stored["carol"]
    # the instructor's class summary lists carol under "needs a person", with the evidence
    with httpx.Client(timeout=60) as client:
        page = client.get(f"{server.url}/instructor/hull/summary/",
                          headers={"Authorization": f"Bearer {server.tokens()['prof']}"})
    assert page.status_code == 200
    text = html.unescape(page.text)
    assert f"{alices} is the answer of alice's variant" in text
    assert text.count("is the answer of") == 1  # carol only: alice and bob are honest
