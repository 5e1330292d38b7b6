"""Access and bad input through a real server: tokens, other students' ids, forged forms, limits."""

from __future__ import annotations

import re

import httpx
import pytest
import svc_support as support
from conftest import MAX_BYTES, PER_HOUR, Running
from sqlalchemy import text

SOLUTION = (support.HULL_EXAMPLES / "solution.ipynb").read_bytes()
SMALL = (support.HULL_EXAMPLES / "partial-only-orientation.ipynb").read_bytes()


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}", "Accept": "application/json"}


def stored(service: Running) -> tuple[int, int]:
    """(submissions in the database, files in the upload store)."""
    with service.engine.connect() as db:
        count = db.execute(text("SELECT count(*) FROM submissions")).scalar_one()
    files = sum(1 for p in (service.data / "uploads").rglob("*.ipynb")) if (service.data / "uploads").exists() else 0
    return count, files


@pytest.fixture(scope="module")
def client() -> httpx.Client:
    with httpx.Client(timeout=60) as c:
        yield c


def test_missing_or_wrong_token(service: Running, client: httpx.Client) -> None:
    assert client.get(f"{service.url}/api/submissions/1").status_code == 401
    page = client.get(f"{service.url}/assignments")
    assert page.status_code == 303 and page.headers["location"].startswith("/login")
    assert client.get(f"{service.url}/api/submissions/1", headers=bearer("not-a-token")).status_code == 401
    answer = support.upload(client, service.url, "not-a-token", "hull", SMALL)
    assert answer.status_code == 401 and "Bearer" in answer.json()["error"]
    # a reverse-proxy header is ignored when the course does not configure one
    page = client.get(f"{service.url}/assignments", headers={"X-Remote-User": "prof"})
    assert page.status_code == 303


def test_another_students_submission_is_not_found(service: Running, client: httpx.Client) -> None:
    mine = support.upload(client, service.url, service.tokens["dave"], "hull", SMALL)
    assert mine.status_code == 201, mine.text
    sub_id = mine.json()["id"]
    support.wait_graded(client, service.url, service.tokens["dave"], sub_id)
    for path in (f"/api/submissions/{sub_id}", f"/submissions/{sub_id}",
                 f"/submissions/{sub_id}/feedback"):
        assert client.get(service.url + path, headers=bearer(service.tokens["dave"])).status_code == 200
        other = client.get(service.url + path, headers=bearer(service.tokens["bob"]))
        assert other.status_code == 404, path
        assert "Dave" not in other.text and SMALL.decode()[:40] not in other.text
    missing = client.get(f"{service.url}/api/submissions/999999", headers=bearer(service.tokens["bob"]))
    assert missing.status_code == 404  # the same answer as someone else's id
    feedback = client.get(f"{service.url}/submissions/{sub_id}/feedback",
                          headers=bearer(service.tokens["dave"]))
    assert feedback.headers["content-security-policy"].startswith("sandbox")
    assert "script" not in feedback.headers["content-security-policy"]


def test_forged_forms_are_refused(service: Running, client: httpx.Client) -> None:
    before = stored(service)
    with httpx.Client(base_url=service.url, timeout=60) as browser:
        # the sign-in form itself needs its own nonce cookie
        assert browser.post("/login", data={"token": service.tokens["dave"], "csrf": "x"}).status_code == 403
        page = browser.get("/login").text
        nonce = re.search(r'name="csrf" value="([^"]+)"', page).group(1)
        assert browser.post("/login", data={"token": service.tokens["dave"], "csrf": nonce}).status_code == 303
        files = {"notebook": ("hull.ipynb", SMALL, "application/x-ipynb+json")}
        for forged in ({}, {"csrf": "guessed"}):
            answer = browser.post("/assignments/hull/submissions", data=forged, files=files)
            assert answer.status_code == 403 and "reload the page" in answer.text
        assert browser.post("/instructor/hull/regrade", data={"csrf": "x"}).status_code == 403
    assert stored(service) == before


@pytest.mark.parametrize("name, status, words", [
    ("old", 409, "closed on 2020-02-01"),
    ("later", 409, "opens on 2099-01-01"),
    ("nope", 404, "no assignment"),
])
def test_closed_assignments_store_nothing(service: Running, client: httpx.Client, name: str,
                                          status: int, words: str) -> None:
    before = stored(service)
    answer = support.upload(client, service.url, service.tokens["dave"], name, SMALL)
    assert answer.status_code == status and words in answer.json()["error"]
    assert stored(service) == before


def test_bad_files_store_nothing(service: Running, client: httpx.Client) -> None:
    before = stored(service)
    big = b'{"cells": [], "x": "' + b"a" * MAX_BYTES + b'"}'
    answer = support.upload(client, service.url, service.tokens["dave"], "hull", big)
    assert answer.status_code == 413 and "at most" in answer.json()["error"]
    for junk in (b"print('hello')\n", b"\x89PNG\r\n\x1a\n\0\0", b"{\"not\": \"a notebook\"}", b""):
        answer = support.upload(client, service.url, service.tokens["dave"], "hull", junk)
        assert answer.status_code in (400, 422), (junk, answer.text)
        assert "notebook" in answer.json()["error"]
    assert stored(service) == before


def test_hourly_limit_says_how_long_to_wait(service: Running, client: httpx.Client) -> None:
    for _ in range(PER_HOUR):
        assert support.upload(client, service.url, service.tokens["eve"], "hull", SMALL).status_code == 201
    before = stored(service)
    answer = support.upload(client, service.url, service.tokens["eve"], "hull", SMALL)
    assert answer.status_code == 429
    assert 0 < int(answer.headers["retry-after"]) <= 3600
    assert re.search(r"Try again in \d+ minute", answer.json()["error"])
    assert stored(service) == before


def test_roles(service: Running, client: httpx.Client) -> None:
    student = client.get(f"{service.url}/instructor", headers=bearer(service.tokens["bob"]))
    assert student.status_code == 403
    assert client.get(f"{service.url}/instructor/hull/export/grades.csv",
                      headers=bearer(service.tokens["bob"])).status_code == 403
    ta = client.get(f"{service.url}/instructor", headers={"Authorization": f"Bearer {service.tokens['tess']}"})
    assert ta.status_code == 200 and "Regrade every submission" not in ta.text
    assert client.get(f"{service.url}/instructor/hull/export/grades.csv",
                      headers=bearer(service.tokens["tess"])).status_code == 200
    assert client.post(f"{service.url}/instructor/hull/regrade",
                       headers=bearer(service.tokens["tess"])).status_code == 403
    assert client.post(f"{service.url}/instructor/tokens",
                       headers=bearer(service.tokens["tess"])).status_code == 403
    # a teaching assistant may read any student's attempt (to help), a student only their own
    with service.engine.connect() as db:
        any_id = db.execute(text("SELECT id FROM submissions WHERE user_id = 'dave' LIMIT 1")).scalar()
    if any_id is not None:
        assert client.get(f"{service.url}/api/submissions/{any_id}",
                          headers=bearer(service.tokens["tess"])).status_code == 200


def test_pages_carry_a_strict_policy(service: Running, client: httpx.Client) -> None:
    page = client.get(f"{service.url}/login")
    policy = page.headers["content-security-policy"]
    assert "script-src 'self'" in policy and "default-src 'none'" in policy
    assert "frame-ancestors 'none'" in policy
    script = client.get(f"{service.url}/static/service.js")
    assert script.status_code == 200 and "http" not in script.text  # nothing remote


def test_roster_command_adds_people_with_working_tokens(service: Running, client: httpx.Client,
                                                        tmp_path) -> None:
    import csv
    import subprocess
    import sys

    roster = tmp_path / "more.csv"
    roster.write_text("id,name,email\nfrank,Frank,frank@example.edu\nbob,Bob B.,bob@example.edu\n")
    tokens = tmp_path / "new-tokens.csv"
    run = subprocess.run([sys.executable, "-m", "autograder", "roster", str(service.server.course),
                          str(roster), "--database", service.server.database, "--tokens", str(tokens)],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "Imported 2 people" in run.stdout and str(tokens) in run.stdout
    rows = list(csv.DictReader(tokens.open()))
    assert [r["id"] for r in rows] == ["frank"]  # bob keeps the token he has
    assert oct(tokens.stat().st_mode & 0o777) == "0o600"
    assert client.get(f"{service.url}/assignments",
                      headers=bearer(rows[0]["token"])).status_code == 200
    with service.engine.connect() as db:
        stored_hash = db.execute(text("SELECT token_hash FROM users WHERE id = 'frank'")).scalar_one()
    assert rows[0]["token"] not in stored_hash and len(stored_hash) == 64
    # the instructor's download: only people without a token get one ("missing")
    answer = client.post(f"{service.url}/instructor/tokens", data={"scope": "missing"},
                         headers={"Authorization": f"Bearer {service.tokens['prof']}"})
    assert answer.status_code == 200 and answer.headers["content-type"].startswith("text/csv")
    assert answer.text.strip() == "id,name,email,role,token"
