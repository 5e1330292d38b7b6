"""The service grading on Dask (``autograder serve --dask``) through a real server.

One service grades on a ``local:1`` cluster for the module: the scores are
those of local grading (the bands of ``assignments/hull/examples/expected.toml``
and the same result keys), the feedback page is served, and a SIGKILL leaves no
process behind and no job graded twice. A second service points
at a port nobody listens on: its submissions get "error" results, retried,
shown to the instructor, never a zero. SQLite only: the queue's PostgreSQL path
is the local graders' (tests/service/test_flows.py runs both).
"""

from __future__ import annotations

import hashlib
import subprocess
import sys
import time
import tomllib
from collections.abc import Iterator
from pathlib import Path

import httpx
import nbformat
import pytest
from sqlalchemy import text

pytest.importorskip("distributed", reason="grading on Dask needs the dask extra: pip install -e '.[dask]'")

import svc_support as support  # noqa: E402
from conftest import CLASS, Running  # noqa: E402

from autograder.engine.assignment import load_assignment  # noqa: E402
from autograder.engine.grader import GradingOptions, submission_key  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

EXPECTED = tomllib.loads((support.HULL_EXAMPLES / "expected.toml").read_text())
NOTEBOOKS = {name: (support.HULL_EXAMPLES / f"{name}.ipynb").read_bytes()
             for name in ("solution", "wrong-clockwise")}


def dask_course(folder: Path, *, max_tries: int = 3) -> Path:
    """hull, open until 2099 (no late penalty), graded with every check."""
    body = f"""
[course]
name = "Dask service course"
roster = "roster.csv"
data = "data"
max_tries = {max_tries}

[[assignment]]
name = "hull"
title = "Convex hull"
opens = 2020-01-01T00:00:00Z
deadline = 2099-01-01T00:00:00Z
"""
    return support.write_course(folder, body=body, roster=CLASS)


def start(folder: Path, dask: str, *options: str, max_tries: int = 3) -> Running:
    server = support.Server(dask_course(folder, max_tries=max_tries), f"sqlite:///{folder / 'course.sqlite3'}",
                            dask=dask, options=options)
    server.start()
    return Running(server)


def stop(running: Running) -> None:
    running.engine.dispose()
    running.server.stop()


@pytest.fixture(scope="module")
def on_dask(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Running]:
    running = start(tmp_path_factory.mktemp("dask-course"), "local:1")
    try:
        yield running
    finally:
        stop(running)


def test_scores_and_feedback_are_those_of_local_grading(on_dask: Running) -> None:
    hull = load_assignment("hull")
    with httpx.Client(timeout=60) as client:
        sent = {name: (who, support.upload(client, on_dask.url, on_dask.tokens[who], "hull", data).json())
                for (name, data), who in zip(NOTEBOOKS.items(), ("alice", "bob"))}
        for name, (who, sub) in sent.items():
            auth = {"Authorization": f"Bearer {on_dask.tokens[who]}"}
            view = support.wait_graded(client, on_dask.url, on_dask.tokens[who], sub["id"])
            assert view["status"] == "graded", view
            band = EXPECTED[name]
            assert band["min"] <= view["raw_score"] / view["max_score"] <= band["max"], (name, view)
            assert view["score"] == view["raw_score"]  # on time: no penalty
            page = client.get(f"{on_dask.url}/submissions/{sub['id']}/feedback", headers=auth)
            assert page.status_code == 200 and "sandbox" in page.headers["content-security-policy"]
            for phrase in band.get("contains", []):
                assert phrase in page.text, (name, phrase)
            with on_dask.engine.connect() as db:
                row = db.execute(text("SELECT s.result_json, s.result_dir, g.worker FROM submissions s "
                                      "JOIN gradings g ON g.submission_id = s.id WHERE s.id = :s"),
                                 {"s": sub["id"]}).one()
            # the same grading as a local grader's: same notebook, assignment, engine and options
            sha = hashlib.sha256(NOTEBOOKS[name]).hexdigest()
            assert f'"key": "{submission_key(sha, hull, GradingOptions())}"' in row.result_json
            assert f'"id": "{who}"' in row.result_json
            assert row.worker.endswith("(dask)")
            folder = on_dask.data / row.result_dir  # grade_job's layout: results.json, feedback.html
            assert (folder / "results.json").is_file() and (folder / "feedback.html").is_file()


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (the dispatcher, the Dask worker, its sandboxed workers)."""
    found, todo = [], [pid]
    while todo:
        for task in Path(f"/proc/{todo.pop()}/task").glob("*"):
            try:
                children = [int(c) for c in (task / "children").read_text().split()]
            except OSError:
                continue
            found += children
            todo += children
    return found


def test_killed_service_leaves_no_process_and_its_job_is_graded_once(on_dask: Running) -> None:
    """SIGKILL while a grading is out: the dispatcher and the cluster die with the service; after
    a restart the job's lease runs out and it is graded exactly once."""
    slow = nbformat.reads(NOTEBOOKS["solution"].decode(), as_version=4)
    slow.cells.insert(0, nbformat.v4.new_code_cell("import time\ntime.sleep(8)"))
    token = on_dask.tokens["dave"]
    with httpx.Client(timeout=60) as client:
        sub = support.upload(client, on_dask.url, token, "hull", nbformat.writes(slow).encode()).json()
        deadline = time.monotonic() + 300
        while client.get(f"{on_dask.url}/api/submissions/{sub['id']}",
                         headers={"Authorization": f"Bearer {token}"}).json()["status"] != "running":
            assert time.monotonic() < deadline, "the job was never claimed"
            time.sleep(0.2)
        time.sleep(1.0)  # the task reaches the worker
        assert on_dask.server.proc is not None
        below = descendants(on_dask.server.proc.pid)
        assert len(below) >= 3, below  # at least the dispatcher, the Dask worker, its sandboxed worker
        on_dask.server.kill()
        deadline = time.monotonic() + 30
        while [pid for pid in below if support.alive(pid)] and time.monotonic() < deadline:
            time.sleep(0.2)
        assert below and not [pid for pid in below if support.alive(pid)], \
            "processes of the killed service are still running"
        on_dask.server.start()
        view = support.wait_graded(client, on_dask.url, token, sub["id"])
    assert view["status"] == "graded" and view["score"] == view["max_score"] > 0, view
    with on_dask.engine.connect() as db:
        tries = db.execute(text("SELECT tries FROM jobs WHERE submission_id = :s"),
                           {"s": sub["id"]}).scalar_one()
        rows = db.execute(text("SELECT count(*) FROM gradings WHERE submission_id = :s"),
                          {"s": sub["id"]}).scalar_one()
    assert tries == 2 and rows == 1


def test_unreachable_scheduler_gives_retried_errors_never_a_zero(tmp_path: Path) -> None:
    # nothing listens there; each try waits one second for it (not the default ten)
    running = start(tmp_path, f"tcp://127.0.0.1:{support.free_port()}", "--dask-connect-timeout", "1")
    try:
        with httpx.Client(timeout=60) as client:
            sub = support.upload(client, running.url, running.tokens["carol"], "hull",
                                 NOTEBOOKS["solution"]).json()
            view = support.wait_graded(client, running.url, running.tokens["carol"], sub["id"])
            assert view["status"] == "error" and view["score"] is None and view["raw_score"] is None
            assert "not a zero" in view["message"]
            with running.engine.connect() as db:
                job = db.execute(text("SELECT state, tries, error FROM jobs WHERE submission_id = :s"),
                                 {"s": sub["id"]}).one()
            assert job.state == "failed" and job.tries == 3, job
            assert "Could not reach the Dask scheduler" in job.error
            staff = client.get(f"{running.url}/instructor",
                               headers={"Authorization": f"Bearer {running.tokens['prof']}"}).text
            failed = staff.split('id="failed"')[1].split("</table>")[0]
            assert "carol" in failed and "hull" in failed
    finally:
        stop(running)


def test_a_job_that_shared_a_killers_death_is_graded_alone_not_failed(tmp_path: Path) -> None:
    """Two jobs out on one worker with two grading slots: dave's kills the worker while carol's
    waits there, and Dask (no death allowed) fails both. With one try per job, carol's is sent
    again alone and graded; dave's kills the worker alone and fails."""
    from tests.dask import dask_test_plugins

    marks = tmp_path / "marks"
    marks.mkdir()
    with dask_test_plugins.shared_death_cluster(marks, killer="dave", witness="carol") as address:
        running = start(tmp_path / "course", address, max_tries=1)
        try:
            with httpx.Client(timeout=60) as client:
                sent = {who: support.upload(client, running.url, running.tokens[who], "hull",
                                            NOTEBOOKS["solution"]).json()["id"]
                        for who in ("dave", "carol")}  # dave's job is claimed first
                views = {who: support.wait_graded(client, running.url, running.tokens[who], sub)
                         for who, sub in sent.items()}
            with running.engine.connect() as db:
                jobs = {who: db.execute(text("SELECT state, tries FROM jobs WHERE submission_id = :s"),
                                        {"s": sub}).one() for who, sub in sent.items()}
        finally:
            stop(running)
    assert (marks / "dave.shared").exists(), "dave's grading never killed the worker carol's was on"
    assert views["carol"]["status"] == "graded", views["carol"]
    assert views["carol"]["score"] == views["carol"]["max_score"] > 0
    assert (jobs["carol"].state, jobs["carol"].tries) == ("done", 1)
    assert views["dave"]["status"] == "error" and views["dave"]["score"] is None
    assert (jobs["dave"].state, jobs["dave"].tries) == ("failed", 1)


def test_serve_names_the_extra_and_refuses_jobs_with_dask(tmp_path: Path) -> None:
    course = dask_course(tmp_path)

    def serve(*options: str, prelude: str = "") -> subprocess.CompletedProcess[str]:
        code = (f"import sys; {prelude}from autograder.cli import main; "
                f"sys.exit(main(['serve', {str(course)!r}, *{list(options)!r}]))")
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=300, cwd=tmp_path)

    both = serve("--dask", "local:1", "--jobs", "2")
    assert both.returncode == 2 and "give one of the two" in both.stderr, both.stderr
    missing = serve("--dask", "local:1", prelude="sys.modules['distributed'] = None; ")
    assert missing.returncode == 2 and "numgrade[dask]" in missing.stderr, missing.stderr
