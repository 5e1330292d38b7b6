"""The student's install (issue 27 point 4): the one line of README, against a running
service, in a fresh venv holding only what that line installs; then ``autograder check``
and ``autograder submit`` from it, and the submission graded by the service."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import httpx
import pytest

from autograder import api
from autograder.service.install import WHEEL, forbidden_members
from tests.service import svc_support as support

pytestmark = [pytest.mark.slow, pytest.mark.layouts]

ROOT = Path(__file__).resolve().parents[2]
SOLUTION = ROOT / "assignments" / "hull" / "examples" / "solution.ipynb"
COURSE = """
[course]
name = "Student install course"
roster = "roster.csv"
data = "data"

[[assignment]]
name = "hull"
title = "Convex hull"
opens = 2020-01-01T00:00:00Z
deadline = 2099-01-01T00:00:00Z
"""


def venv_python(folder: Path) -> Path:
    """A fresh venv, as a student makes one: nothing of this machine's site-packages."""
    subprocess.run([sys.executable, "-m", "venv", str(folder)], check=True, timeout=300)
    return folder / "bin" / "python"


def run(python: Path, *args: str, cwd: Path, timeout: float = 1200) -> subprocess.CompletedProcess[str]:
    env = {"PATH": f"{python.parent}:/usr/bin:/bin", "HOME": str(cwd)}  # no PYTHONPATH
    return subprocess.run([str(python), *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=timeout)


def test_install_check_and_submit_from_the_services_wheel(tmp_path: Path) -> None:
    course = support.write_course(tmp_path / "course", body=COURSE,
                                  roster=[("alice", "Alice", "alice@example.edu", "student")])
    server = support.Server(course, f"sqlite:///{tmp_path / 'db.sqlite3'}", jobs=1).start()
    try:
        page = httpx.get(server.url + "/install", timeout=60).text
        command = re.search(r"<code>(python -m pip install [^<]+)</code>", page)
        assert command, page
        line = command.group(1).replace("&quot;", '"')
        url = re.search(r'"(\S+)"', line).group(1)
        assert url == f"{server.url}/install/{WHEEL}"
        wheel = tmp_path / WHEEL  # what is served holds nothing a student must not see
        wheel.write_bytes(httpx.get(url, timeout=900).content)
        assert forbidden_members(wheel) == []
        assert httpx.get(server.url + "/install/numgrade.whl").status_code == 404

        python = venv_python(tmp_path / "venv")
        installed = run(python, "-m", "pip", "install", "--quiet", url, cwd=tmp_path)
        assert installed.returncode == 0, installed.stderr[-3000:]
        files = run(python, "-c", "import importlib.metadata as m; print('\\n'.join(map(str, "
                    "m.files('numgrade'))))", cwd=tmp_path).stdout.split()
        assert files and all(f.startswith(("autograder/", "numgrade-", "../../../bin/"))
                             for f in files), files
        assert not [f for f in files if "hidden" in f or "reference" in f.split("/")[0]]
        stack = run(python, "-c", "import importlib.util as u; print([m for m in ('fastapi', "
                    "'sqlalchemy', 'uvicorn', 'httpx', 'nbgrader') if u.find_spec(m)])",
                    cwd=tmp_path)
        assert stack.stdout.strip() == "[]", stack.stdout + stack.stderr

        release = tmp_path / "release"
        api.release("hull", out=release)
        (release / "hull.ipynb").write_bytes(SOLUTION.read_bytes())  # the student's answers
        checked = run(python, "-m", "autograder", "check", "hull.ipynb", cwd=release)
        assert checked.returncode == 0, checked.stdout + checked.stderr
        assert re.search(r"Public checks: (\S+)/\1 points", checked.stdout), checked.stdout

        submitted = run(python, "-m", "autograder", "submit", "hull.ipynb", "--server",
                        server.url, "--token", server.tokens()["alice"], cwd=release)
        assert submitted.returncode == 0, submitted.stdout + submitted.stderr
        score = re.search(r"^Score: ([\d.]+)/([\d.]+)$", submitted.stdout, re.M)
        assert score and float(score[1]) == float(score[2]) > 0, submitted.stdout
        attempt = re.search(r"Attempt (\d+)", submitted.stdout)[1]
        mine = httpx.get(f"{server.url}/api/submissions/{attempt}",
                         headers={"Authorization": f"Bearer {server.tokens()['alice']}"}).json()
        assert mine["status"] == "graded" and mine["score"] == float(score[1])
    finally:
        server.stop()


def test_a_wrong_token_is_a_message_not_a_traceback(tmp_path: Path) -> None:
    """The urllib client: a 401 and an unreachable service are messages naming the fix."""
    notebook = tmp_path / "hull.ipynb"
    notebook.write_bytes(SOLUTION.read_bytes())
    for server in ("http://127.0.0.1:9", "ftp://example.edu"):
        done = subprocess.run([sys.executable, "-m", "autograder", "submit", str(notebook),
                               "--server", server, "--token", "x"], cwd=ROOT,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
        assert "service" in done.stderr or "http" in done.stderr


def test_a_request_during_a_build_is_told_to_retry_and_never_waits(tmp_path: Path) -> None:
    """Anyone may ask for the wheel: a request that waited for a build in progress would hold
    a worker thread, and enough of them would stall the service."""
    from autograder.service import install

    assert install._LOCK.acquire(blocking=False)
    try:
        with pytest.raises(install.BuildInProgress, match="being built"):
            install.build_student_wheel(tmp_path / "install")
    finally:
        install._LOCK.release()
    assert not (tmp_path / "install").exists()
