"""The same scores in every install layout a user has (issue: verdicts that hold in every setup).

Each test builds a real layout (venvs with their own numpy, scipy, matplotlib and
IPython; see ``tests/support/envs.py``), grades the model solution and one wrong
answer through the installed ``autograder`` command, and compares every check's
score with the developer's install. A sandbox that cannot read what Python needs
must show up here as a failure, never as a 0 for the student.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.support import envs

ROOT = envs.ROOT
EXAMPLES = ROOT / "assignments" / "hull" / "examples"
GRADED = ("solution", "wrong-clockwise")

pytestmark = [pytest.mark.slow, pytest.mark.layouts]


def scores(results: Path) -> dict[str, dict[str, float]]:
    """``{id: {check: score}}`` read from ``results/<id>/results.json``."""
    found = {}
    for path in sorted(results.glob("*/results.json")):
        data = json.loads(path.read_text())
        extra = data["extra_data"]
        assert extra["outcome"] == "graded", (path, data["output"])
        found[extra["id"]] = {t["name"]: t["score"] for t in data["tests"]}
    return found


def submissions(folder: Path) -> list[str]:
    """The graded examples copied into ``folder`` (world-readable) as nbgrader lays them out."""
    paths = []
    for name in GRADED:
        target = folder / "submitted" / name / "hull" / "hull.ipynb"
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(EXAMPLES / f"{name}.ipynb", target)
        paths.append(str(target))
    envs._open_up(folder)
    return paths


@pytest.fixture(scope="module")
def workspace() -> Path:
    path = envs.shared_tempdir("numgrade-layouts-")
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope="module")
def repo(workspace: Path) -> Path:
    return envs.copy_repository(workspace / "repo")


@pytest.fixture(scope="module")
def expected(workspace: Path) -> dict[str, dict[str, float]]:
    """The scores the developer's own install gives."""
    out = workspace / "baseline"
    proc = subprocess.run([sys.executable, "-m", "autograder", "grade", "hull",
                           *submissions(workspace / "baseline-in"), "--out", str(out),
                           "--no-progress"], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr
    found = scores(out)
    assert set(found) == set(GRADED)
    assert sum(found["solution"].values()) > sum(found["wrong-clockwise"].values()) > 0
    return found


def grade_with(env: envs.Env, assignment: str, folder: Path, *, cwd: Path) -> dict[str, dict[str, float]]:
    out = folder / "results"
    out.mkdir(parents=True, exist_ok=True)
    if env.user is not None:
        shutil.chown(out, env.user, env.user)
    proc = env.run("autograder", "grade", assignment, *submissions(folder / "in"),
                   "--out", str(out), "--no-progress", cwd=cwd)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return scores(out)


def test_venv_inside_the_repository(repo: Path, expected: dict[str, dict[str, float]]) -> None:
    env = envs.make_venv(repo / ".venv", install=["-e", str(repo), "-e", str(repo / "reference")])
    assert grade_with(env, "hull", repo / "class", cwd=repo) == expected


def test_venv_beside_the_repository(repo: Path, workspace: Path,
                                    expected: dict[str, dict[str, float]]) -> None:
    env = envs.make_venv(workspace / "venv-beside",
                         install=["-e", str(repo), "-e", str(repo / "reference")])
    assert grade_with(env, "hull", workspace / "beside", cwd=workspace) == expected


def test_installed_package_with_an_assignment_folder_outside(
        repo: Path, workspace: Path, expected: dict[str, dict[str, float]]) -> None:
    """``pip install .`` (not editable) and the assignment given by its path."""
    env = envs.make_venv(workspace / "venv-wheel", install=[str(repo), str(repo / "reference")])
    course = workspace / "elsewhere"
    shutil.copytree(repo / "assignments" / "hull", course / "hull",
                    ignore=shutil.ignore_patterns("examples"))
    assert grade_with(env, str(course / "hull"), course, cwd=course) == expected


def test_student_checks_in_a_release_folder_beside_their_venv(repo: Path, workspace: Path) -> None:
    """The student's install (no model solutions) next to the released folder."""
    course = workspace / "student"
    released = course / "hull"
    proc = subprocess.run([sys.executable, "-m", "autograder", "release", "hull", "--out",
                           str(released)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    shutil.copy(EXAMPLES / "solution.ipynb", released / "hull.ipynb")
    env = envs.make_venv(course / "venv", install=[str(repo)])
    probe = env.run("python", "-c", "import reference")
    assert probe.returncode != 0, "the student's install must not contain the model solutions"
    proc = env.run("autograder", "check", "hull/hull.ipynb", cwd=course)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PASS" in proc.stdout and "FAIL" not in proc.stdout


def test_gradescope_zip_installed_by_its_own_setup_script(
        workspace: Path, expected: dict[str, dict[str, float]]) -> None:
    """setup.sh and run_autograder exactly as Gradescope runs them, under a fake /autograder."""
    root = workspace / "gradescope"
    proc = subprocess.run([sys.executable, "-m", "autograder", "gradescope", "hull", "--out",
                           str(workspace)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    with zipfile.ZipFile(workspace / "hull-gradescope.zip") as archive:
        names = archive.namelist()
        archive.extractall(root / "source")
    assert "assignment/hull/hull.ipynb" in names
    bundled = (root / "source" / "assignment" / "hull" / "hull.ipynb").read_text()
    assert "### BEGIN SOLUTION" not in bundled, "the zip must not hold the instructor notebook"
    for script in ("setup.sh", "run_autograder"):
        (root / "source" / script).chmod(0o755)
    env = {"AUTOGRADER_ROOT": str(root)}
    setup = subprocess.run(["bash", str(root / "source" / "setup.sh")], capture_output=True,
                           text=True, timeout=envs.INSTALL_TIMEOUT,
                           env={**os.environ, **env}, cwd=root / "source")
    assert setup.returncode == 0, setup.stdout[-3000:] + setup.stderr[-3000:]
    for name in GRADED:
        (root / "submission").mkdir(parents=True, exist_ok=True)
        for old in (root / "submission").iterdir():
            old.unlink()
        shutil.copy(EXAMPLES / f"{name}.ipynb", root / "submission" / "hull.ipynb")
        run = subprocess.run([str(root / "source" / "run_autograder")], capture_output=True,
                             text=True, timeout=900, env={**os.environ, **env})
        assert run.returncode == 0, run.stdout + run.stderr
        data = json.loads((root / "results" / "results.json").read_text())
        assert data["extra_data"]["outcome"] == "graded", data["output"]
        assert {t["name"]: t["score"] for t in data["tests"]} == expected[name]


def test_ordinary_user_with_debians_python(repo: Path, workspace: Path,
                                           expected: dict[str, dict[str, float]]) -> None:
    """Not root, another Python (Debian's 3.11), a non-editable install in the user's home."""
    reason = envs.can_switch_users()
    if reason is not None:
        pytest.skip(f"ordinary-user layout not tested: {reason}")
    if not Path("/usr/bin/python3").exists():
        pytest.skip("ordinary-user layout not tested: Debian's /usr/bin/python3 is missing")
    user = envs.ordinary_user()
    venv = Path(envs.home(user)) / "numgrade-venv"
    if not (venv / "bin" / "autograder").exists():
        envs.make_venv(venv, install=[str(repo), str(repo / "reference")],
                       python="/usr/bin/python3", user=user)
    env = envs.Env(python=venv / "bin" / "python", user=user)
    course = workspace / "user-course"
    shutil.copytree(repo / "assignments" / "hull", course / "hull",
                    ignore=shutil.ignore_patterns("examples"))
    envs._open_up(course)
    assert grade_with(env, str(course / "hull"), course, cwd=course) == expected
