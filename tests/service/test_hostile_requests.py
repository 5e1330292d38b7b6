"""Hostile requests: huge forms, endless chunked uploads, refused uploads, token guessing,
old sessions and a second roster.

Where streaming matters the attack is a raw socket against the real ``autograder
serve`` (uvicorn): the client sends the body chunk by chunk until the server
answers or stops reading, and the bytes it could send bound what the server can
have read or spooled. An honest student's requests run at the same time and
must be answered. The rest runs the same application in this process
(``TestClient``) where a test needs to count what the service did: the
notebook parses and the body bytes read for a refused upload.
"""

from __future__ import annotations

import csv
import datetime as dt
import http.client
import re
import select
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
import pytest
import svc_support as support
from conftest import PER_HOUR, Running, class_course
from sqlalchemy import text

from autograder.service.settings import FORM_BYTES, SIGN_IN_FAILURES, SIGN_IN_WINDOW_MINUTES

SMALL = (support.HULL_EXAMPLES / "partial-only-orientation.ipynb").read_bytes()
MB = 1024 * 1024
#: the attack's body; without a bound the server reads all of it
ATTACK_BYTES = 96 * MB
#: what the client may get into the server before it stops reading: the limit, uvicorn's
#: 64 KB read-ahead and the kernel's socket buffers on both sides (autotuned, some MB)
READ_BOUND = 40 * MB


def bearer(token: str, address: str | None = None) -> dict[str, str]:
    headers = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    if address:
        headers["X-Forwarded-For"] = address  # uvicorn believes it from 127.0.0.1
    return headers


# -- a raw HTTP client that streams a body until the server refuses it ---------------

@dataclass
class Attack:
    sent: int  # body bytes the server's socket accepted
    status: int | None
    headers: dict[str, str]
    body: bytes


def endless(first: bytes = b"", size: int = ATTACK_BYTES, chunk: int = 64 * 1024) -> Iterator[bytes]:
    yield first
    filler = b"a" * chunk
    for _ in range(size // chunk):
        yield filler


def stream(port: int, path: str, headers: dict[str, str], chunks: Iterator[bytes], *,
           chunked: bool, finish: bool = True) -> Attack:
    """POST ``chunks`` as the body (chunked, or under the given ``Content-Length``), stopping as
    soon as the server answers or stops reading; then read the answer."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=120)
    lines = [f"POST {path} HTTP/1.1", "Host: 127.0.0.1"] + [f"{k}: {v}" for k, v in headers.items()]
    if chunked:
        lines.append("Transfer-Encoding: chunked")
    sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
    sent = 0
    try:
        for chunk in chunks:
            if select.select([sock], [], [], 0)[0]:
                break  # the server has answered (or closed): stop, as a client would
            sock.sendall(b"%x\r\n%s\r\n" % (len(chunk), chunk) if chunked else chunk)
            sent += len(chunk)
        else:
            if chunked and finish:
                sock.sendall(b"0\r\n\r\n")
    except (BrokenPipeError, ConnectionResetError):
        pass  # the server closed the connection: what it read is at most ``sent``
    except TimeoutError:
        raise AssertionError(f"the server neither read nor refused the body after {sent} bytes") from None
    try:
        response = http.client.HTTPResponse(sock)
        response.begin()
        return Attack(sent, response.status, dict(response.getheaders()), response.read())
    except (ConnectionResetError, http.client.RemoteDisconnected):
        return Attack(sent, None, {}, b"")
    finally:
        sock.close()


def while_attacked(service: Running, attack: Any) -> tuple[Attack, list[int]]:
    """Run ``attack()`` in a thread; meanwhile an honest student keeps reading their pages."""
    result: list[Attack] = []
    thread = threading.Thread(target=lambda: result.append(attack()), daemon=True)
    honest: list[int] = []
    with httpx.Client(timeout=120) as client:
        thread.start()
        while thread.is_alive() or not honest:
            honest.append(client.get(f"{service.url}/assignments/hull",
                                     headers=bearer(service.tokens["alice"])).status_code)
        thread.join(timeout=600)
    assert not thread.is_alive() and result, "the attack did not finish"
    return result[0], honest


def server_port(service: Running) -> int:
    return service.server.port


# -- bodies: forms and uploads are bounded while they stream ----------------------------

BOUNDARY = "hostile-boundary"
#: the start of a form part holding a file: Starlette spools such a part to a temporary file
FILE_PART = (f"--{BOUNDARY}\r\nContent-Disposition: form-data; name=\"notebook\"; "
             "filename=\"hull.ipynb\"\r\nContent-Type: application/x-ipynb+json\r\n\r\n").encode()


@pytest.mark.parametrize("kind", ["urlencoded", "multipart-file"])
def test_an_endless_sign_in_form_is_refused_at_its_limit(service: Running, kind: str) -> None:
    if kind == "urlencoded":
        headers, first = {"Content-Type": "application/x-www-form-urlencoded"}, b"csrf=x&token="
    else:  # a file part in the sign-in form, which Starlette would spool to disk whole
        headers = {"Content-Type": f"multipart/form-data; boundary={BOUNDARY}"}
        first = FILE_PART.replace(b"notebook", b"token")
    attack, honest = while_attacked(service, lambda: stream(
        server_port(service), "/login", headers, endless(first), chunked=True))
    assert attack.status == 413, attack
    assert b"larger than 64 KB" in attack.body
    assert attack.sent < READ_BOUND, f"the server read {attack.sent / MB:.0f} MB of a sign-in form"
    assert set(honest) == {200}


def test_a_sign_in_form_announcing_a_huge_length_is_refused_unread(service: Running) -> None:
    headers = {"Content-Type": "application/x-www-form-urlencoded",
               "Content-Length": str(400 * MB)}
    attack = stream(server_port(service), "/login", headers, endless(b"csrf=x&token=", size=MB),
                    chunked=False)
    assert attack.status == 413 and attack.headers.get("connection") == "close", attack
    assert attack.sent <= MB + len(b"csrf=x&token=")


def test_a_chunked_upload_without_length_is_refused_at_the_limit(service: Running) -> None:
    headers = {**bearer(service.tokens["carol"]),
               "Content-Type": f"multipart/form-data; boundary={BOUNDARY}"}
    attack, honest = while_attacked(service, lambda: stream(
        server_port(service), "/assignments/hull/submissions", headers, endless(FILE_PART),
        chunked=True))
    assert attack.status == 413, attack
    assert b"at most" in attack.body and b"nothing was stored" in attack.body
    assert attack.sent < READ_BOUND, f"the server read {attack.sent / MB:.0f} MB of the upload"
    assert set(honest) == {200}


def test_forms_other_than_uploads_are_small(service: Running) -> None:
    """A staff form (here with a valid token) is held to the form limit too."""
    with httpx.Client(timeout=60) as client:
        answer = client.post(f"{service.url}/instructor/extensions",
                             headers=bearer(service.tokens["prof"]),
                             data={"student": "bob", "deadline": "x" * (FORM_BYTES + 1)})
    assert answer.status_code == 413 and "larger than 64 KB" in answer.json()["error"]


# -- the application in this process: counting what a refused upload costs -------------

@dataclass
class Local:
    folder: Path
    course_file: Path
    database: str
    app: Any
    tokens: dict[str, str]
    engine: Any


def build_local(folder: Path) -> Local:
    from autograder.service.app import create_app
    from autograder.service.db import make_engine, sessions
    from autograder.service.server import import_roster, open_course

    course_file = class_course(folder)
    database = f"sqlite:///{folder / 'local.sqlite3'}"
    course = open_course(course_file, database=database)
    import_roster(course, course.roster)
    with (course.data_dir / "tokens.csv").open() as handle:
        tokens = {row["id"]: row["token"] for row in csv.DictReader(handle)}
    engine = make_engine(database)
    return Local(folder, course_file, database, create_app(course, sessions(engine)), tokens, engine)


@pytest.fixture(scope="module")
def local(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Local]:
    built = build_local(tmp_path_factory.mktemp("local"))
    try:
        yield built
    finally:
        built.engine.dispose()


class BodyCounter:
    """ASGI wrapper counting the body bytes the application pulled from the server."""

    def __init__(self, app: Any) -> None:
        self.app, self.read = app, 0

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        async def counted() -> Any:
            message = await receive()
            self.read += len(message.get("body", b""))
            return message
        await self.app(scope, counted, send)


def test_the_hourly_limit_is_checked_before_the_upload_is_read(local: Local,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    from fastapi.testclient import TestClient

    from autograder.service import intake

    parses: list[int] = []
    real_parse = intake.parse_notebook
    monkeypatch.setattr(intake, "parse_notebook", lambda data, **kw: parses.append(1) or real_parse(data, **kw))
    now = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)
    with local.engine.begin() as db:
        for minutes in range(PER_HOUR):
            db.execute(text("INSERT INTO submissions (user_id, assignment, sha256, filename, "
                            "submitted_at, late_days, penalty, status) VALUES ('eve', 'hull', "
                            "'0', 'x.ipynb', :t, 0, 0, 'graded')"),
                       {"t": now - dt.timedelta(minutes=minutes + 1)})
    counter = BodyCounter(local.app)
    files = {"notebook": ("hull.ipynb", SMALL, "application/x-ipynb+json")}
    with TestClient(counter, follow_redirects=False) as client:
        refused = client.post("/assignments/hull/submissions", headers=bearer(local.tokens["eve"]),
                              files=files)
        assert refused.status_code == 429 and 0 < int(refused.headers["retry-after"]) <= 3600
        assert re.search(r"Try again in \d+ minute", refused.json()["error"])
        assert (counter.read, parses) == (0, []), "the refused upload was read and parsed"
        accepted = client.post("/assignments/hull/submissions",
                               headers=bearer(local.tokens["dave"]), files=files)
    assert accepted.status_code == 201 and counter.read >= len(SMALL) and parses == [1]


# -- guessing tokens ------------------------------------------------------------------------

def test_three_hundred_wrong_tokens_are_throttled(service: Running) -> None:
    attacker, honest = "198.51.100.23", "203.0.113.5"
    answers = []
    with httpx.Client(timeout=60) as client:
        for guess in range(300):
            answers.append(client.get(f"{service.url}/api/submissions/1",
                                      headers=bearer(f"guess-{guess}", attacker)))
        codes = [a.status_code for a in answers]
        assert codes[:SIGN_IN_FAILURES] == [401] * SIGN_IN_FAILURES
        assert set(codes[SIGN_IN_FAILURES:]) == {429}, codes
        wait = int(answers[-1].headers["retry-after"])
        assert 0 < wait <= SIGN_IN_WINDOW_MINUTES * 60
        assert "Try again in" in answers[-1].json()["error"]
        # from the locked address even the right token waits: a hit looks like a miss
        right = client.get(f"{service.url}/assignments", headers=bearer(service.tokens["bob"], attacker))
        assert right.status_code == 429
        # the sign-in form from that address is paused too, before its form is read
        page = client.post(f"{service.url}/login", data={"token": service.tokens["bob"], "csrf": "x"},
                           headers={"X-Forwarded-For": attacker})
        assert page.status_code == 429 and "paused" in page.text and page.headers["retry-after"]
        # a student elsewhere is not affected
        mine = client.get(f"{service.url}/assignments", headers=bearer(service.tokens["bob"], honest))
        assert mine.status_code == 200


def test_wrong_tokens_on_the_sign_in_form_are_throttled(service: Running) -> None:
    attacker = "198.51.100.77"
    with httpx.Client(base_url=service.url, timeout=60, headers={"X-Forwarded-For": attacker}) as web:
        nonce = re.search(r'name="csrf" value="([^"]+)"', web.get("/login").text).group(1)
        codes = [web.post("/login", data={"token": f"guess-{i}", "csrf": nonce}).status_code
                 for i in range(SIGN_IN_FAILURES + 5)]
    assert codes == [401] * (SIGN_IN_FAILURES - 1) + [429] * 6, codes


def test_every_service_process_sees_the_same_throttle(service: Running) -> None:
    """A second service process on the same database refuses the address the first locked."""
    from fastapi.testclient import TestClient

    from autograder.service.app import create_app
    from autograder.service.db import make_engine, sessions
    from autograder.service.server import open_course

    attacker = "198.51.100.99"
    with httpx.Client(timeout=60) as client:
        for guess in range(SIGN_IN_FAILURES):
            client.get(f"{service.url}/api/submissions/1", headers=bearer(f"g{guess}", attacker))
    course = open_course(service.server.course, database=service.server.database)
    engine = make_engine(service.server.database)
    try:
        app = create_app(course, sessions(engine))
        with TestClient(app, client=(attacker, 40000)) as other:
            answer = other.get("/assignments", headers=bearer(service.tokens["bob"]))
        assert answer.status_code == 429 and answer.headers["retry-after"]
        with TestClient(app, client=("203.0.113.80", 40000)) as elsewhere:
            assert elsewhere.get("/assignments", headers=bearer(service.tokens["bob"])).status_code == 200
    finally:
        engine.dispose()


# -- browser sessions ------------------------------------------------------------------

def sign_in(web: httpx.Client, token: str) -> httpx.Response:
    nonce = re.search(r'name="csrf" value="([^"]+)"', web.get("/login").text).group(1)
    return web.post("/login", data={"token": token, "csrf": nonce})


def test_browser_sessions_expire(service: Running) -> None:
    with httpx.Client(base_url=service.url, timeout=60,
                      headers={"X-Forwarded-For": "203.0.113.41"}) as web:
        signed = sign_in(web, service.tokens["carol"])
        assert signed.status_code == 303
        assert "max-age=43200" in signed.headers["set-cookie"].lower()  # 12 hours, the default
        assert web.get("/assignments").status_code == 200
        with service.engine.begin() as db:  # the session began 12 hours and a minute ago
            db.execute(text("UPDATE web_sessions SET created_at = :t WHERE user_id = 'carol'"),
                       {"t": dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)
                        - dt.timedelta(hours=12, minutes=1)})
        page = web.get("/assignments")
        assert page.status_code == 303 and page.headers["location"].startswith("/login")


def test_new_tokens_sign_old_browsers_out(tmp_path: Path) -> None:
    from fastapi.testclient import TestClient

    built = build_local(tmp_path)
    try:
        with TestClient(built.app, follow_redirects=False) as web, \
                TestClient(built.app, follow_redirects=False) as staff:
            assert sign_in(web, built.tokens["alice"]).status_code == 303
            assert web.get("/assignments").status_code == 200
            rotated = staff.post("/instructor/tokens", data={"scope": "all"},
                                 headers=bearer(built.tokens["prof"]))
            assert rotated.status_code == 200
            page = web.get("/assignments")
            assert page.status_code == 303 and page.headers["location"].startswith("/login")
            new = {row["id"]: row["token"] for row in csv.DictReader(rotated.text.splitlines())}
            assert sign_in(web, built.tokens["alice"]).status_code == 401  # the old token is dead
            assert sign_in(web, new["alice"]).status_code == 303
            assert web.get("/assignments").status_code == 200
    finally:
        built.engine.dispose()


# -- the roster command --------------------------------------------------------------------

def roster(local: Local, rows: str, *extra: str) -> subprocess.CompletedProcess[str]:
    path = local.folder / "more.csv"
    path.write_text("id,name,email\n" + rows)
    run = subprocess.run([sys.executable, "-m", "autograder", "roster", str(local.course_file),
                          str(path), "--database", local.database, *extra],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return run


def test_a_second_roster_keeps_everyones_tokens(local: Local) -> None:
    tokens_file = local.folder / "data" / "tokens.csv"
    before = {r["id"]: r["token"] for r in csv.DictReader(tokens_file.open())}
    assert set(before) >= {"alice", "bob", "prof"}
    run = roster(local, "gina,Gina,gina@example.edu\nbob,Bob B.,bob@example.edu\n")
    assert "Added (1): gina." in run.stdout
    assert "Already there, name, email and role updated, token kept (1): bob." in run.stdout
    after = {r["id"]: r["token"] for r in csv.DictReader(tokens_file.open())}
    assert {k: after[k] for k in before} == before and "gina" in after
    assert oct(tokens_file.stat().st_mode & 0o777) == "0o600"
    run = roster(local, "hank,Hank,hank@example.edu\ngina,Gina,gina@example.edu\n")
    assert "Added (1): hank." in run.stdout and "(1): gina." in run.stdout
    final = {r["id"]: r["token"] for r in csv.DictReader(tokens_file.open())}
    assert final == {**after, "hank": final["hank"]}
    from fastapi.testclient import TestClient
    with TestClient(local.app) as client:
        for who in ("alice", "gina", "hank"):
            assert client.get("/assignments", headers=bearer(final[who])).status_code == 200, who


def test_every_issued_token_can_follow_token_on_a_command_line() -> None:
    # One bare URL-safe token in 64 began with '-', and `autograder submit --token
    # -x...` then stopped at argparse's "expected one argument" (a CI run failed so).
    from autograder.cli import build_parser
    from autograder.service.auth import new_token

    parser = build_parser()
    for _ in range(2000):
        token = new_token()
        args = parser.parse_args(["submit", "hull.ipynb", "--server", "http://x", "--token", token])
        assert args.token == token
