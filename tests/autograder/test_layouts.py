"""The same scores in every install layout a user has (issue: verdicts that hold in every setup).

Each test builds a real layout (venvs with their own numpy, scipy, matplotlib and
IPython; see ``tests/support/envs.py``), grades the model solution and one wrong
answer through the installed ``autograder`` command, and compares every check's
score with the developer's install. A sandbox that cannot read what Python needs
must show up here as a failure, never as a 0 for the student.

The installs are most of this module's time and each is one core's work, so they
are made two at a time in the background from the first test on (:func:`installs`);
each test waits for its own and then grades as before.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import zipfile
from concurrent.futures import Future
from pathlib import Path
from typing import Any, Callable, Iterator

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


def submissions(folder: Path, copies: int = 1) -> list[str]:
    """The graded examples copied into ``folder`` (world-readable) as nbgrader lays them out;
    with ``copies`` > 1, each that many times, as students ``<example>-<k>``."""
    paths = []
    for k in range(copies):
        for name in GRADED:
            student = name if copies == 1 else f"{name}-{k}"
            target = folder / "submitted" / student / "hull" / "hull.ipynb"
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
def cache(workspace: Path) -> Path:
    """One pip cache for every venv and user of the run: wheels are downloaded once."""
    path = workspace / "pip-cache"
    path.mkdir(mode=0o777)
    path.chmod(0o777)
    return path


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


class Installs:
    """The layouts' installs, made two at a time in the background.

    Two chains of steps, each step a :class:`Future`: installs that write into the
    same checkout (an editable install and a build of it write ``*.egg-info`` there)
    run one after the other in one chain; a failed step fails only its own future.
    """

    def __init__(self, chains: list[list[tuple[str, Callable[[], Any]]]]) -> None:
        self.futures: dict[str, Future[Any]] = {
            name: Future() for chain in chains for name, _ in chain}
        self.threads = [threading.Thread(target=self._run, args=(chain,), daemon=True)
                        for chain in chains]
        for thread in self.threads:
            thread.start()

    def _run(self, chain: list[tuple[str, Callable[[], Any]]]) -> None:
        for name, step in chain:
            future = self.futures[name]
            future.set_running_or_notify_cancel()
            try:
                future.set_result(step())
            except BaseException as exc:  # reported by the test that waits for it
                future.set_exception(exc)

    def get(self, name: str) -> Any:
        return self.futures[name].result(timeout=2 * envs.INSTALL_TIMEOUT)


def _ordinary_user_install(request: pytest.FixtureRequest) -> tuple[envs.Env, Path] | str:
    """The ordinary user's ``pip install .`` from a copy of their own, into a venv in their
    home: the session's (conftest.py), which the engine's other end-to-end tests use too; a
    skip reason if there is none."""
    if envs.can_switch_users() is None and Path("/usr/bin/python3").exists():
        return request.getfixturevalue("ordinary_user_venv")
    return f"ordinary-user layout not tested: {envs.can_switch_users() or 'no /usr/bin/python3'}"


def _own_install(workspace: Path, cache: Path) -> tuple[envs.Env, Path]:
    """Not root: ``pip install .`` (not editable) by the current user, from a copy."""
    source = envs.copy_repository(workspace / "user-src")
    env = envs.make_venv(workspace / "venv-wheel", install=[str(source), str(source / "reference")],
                         cache=cache)
    return env, source


def _gradescope_install(workspace: Path, cache: Path) -> tuple[Path, dict[str, str], list[str]]:
    """The zip from ``autograder gradescope``, unpacked and set up by its own ``setup.sh``."""
    root = workspace / "gradescope"
    proc = subprocess.run([sys.executable, "-m", "autograder", "gradescope", "hull", "--out",
                           str(workspace)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    with zipfile.ZipFile(workspace / "hull-gradescope.zip") as archive:
        names = archive.namelist()
        archive.extractall(root / "source")
    for script in ("setup.sh", "run_autograder"):
        (root / "source" / script).chmod(0o755)
    env = {"AUTOGRADER_ROOT": str(root), "PIP_CACHE_DIR": str(cache)}
    setup = subprocess.run(["bash", str(root / "source" / "setup.sh")], capture_output=True,
                           text=True, timeout=envs.INSTALL_TIMEOUT,
                           env={**os.environ, **env}, cwd=root / "source")
    assert setup.returncode == 0, setup.stdout[-3000:] + setup.stderr[-3000:]
    return root, env, names


@pytest.fixture(scope="module")
def installs(repo: Path, workspace: Path, cache: Path,
             request: pytest.FixtureRequest) -> Iterator[Installs]:
    """Every layout's install, started when the first test of the module asks; the ordinary
    user's is the session's (built here, while the others install, if no test needed it yet)."""
    student = workspace / "student"
    # A suite run from a venv: ``--system-site-packages`` would give the beside venv the
    # *base* interpreter's packages, not this venv's, so it gets its own install.
    in_venv = sys.prefix != sys.base_prefix
    # The student's install is built from a copy of its own (a build writes into its source),
    # so it need not wait for the editable installs of ``repo``: as root, the ordinary
    # user's venv is the session's, and the student's takes its place in the second chain.
    as_root = os.geteuid() == 0
    student_step = ("student", lambda: envs.make_venv(
        student / "venv", install=[str(envs.copy_repository(workspace / "student-src"))],
        cache=cache))
    chains: list[list[tuple[str, Callable[[], Any]]]] = [[
        ("inside", lambda: envs.make_venv(
            repo / ".venv", install=["-e", str(repo), "-e", str(repo / "reference")], cache=cache)),
        ("beside", lambda: envs.make_venv(
            workspace / "venv-beside", stack=in_venv, system_site=not in_venv, cache=cache,
            install=[*([] if in_venv else ["--no-deps"]), "-e", str(repo),
                     "-e", str(repo / "reference")])),
        *([] if as_root else [student_step]),
    ], [
        *([student_step] if as_root else [("user", lambda: _own_install(workspace, cache))]),
        ("gradescope", lambda: _gradescope_install(workspace, cache)),
    ]]
    made = Installs(chains)
    if as_root:  # the session's venv: a fixture, so asked for in this thread
        user: Future[Any] = Future()
        made.futures["user"] = user
        try:
            user.set_result(_ordinary_user_install(request))
        except Exception as exc:  # reported by the tests that wait for it, as for the others
            user.set_exception(exc)
    yield made
    for thread in made.threads:
        thread.join(timeout=2 * envs.INSTALL_TIMEOUT)


def test_venv_inside_the_repository(repo: Path, installs: Installs,
                                    expected: dict[str, dict[str, float]]) -> None:
    """``python -m venv .venv`` in the checkout, numpy and the rest inside it."""
    env = installs.get("inside")
    assert grade_with(env, "hull", repo / "class", cwd=repo) == expected


def test_venv_beside_the_repository(workspace: Path, installs: Installs,
                                    expected: dict[str, dict[str, float]]) -> None:
    """A venv next to the checkout (the libraries from the base Python: only the place differs)."""
    env = installs.get("beside")
    assert grade_with(env, "hull", workspace / "beside", cwd=workspace) == expected


def test_student_checks_in_a_release_folder_beside_their_venv(workspace: Path,
                                                              installs: Installs) -> None:
    """The student's install (no model solutions) next to the released folder."""
    course = workspace / "student"
    released = course / "hull"
    proc = subprocess.run([sys.executable, "-m", "autograder", "release", "hull", "--out",
                           str(released)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    shutil.copy(EXAMPLES / "solution.ipynb", released / "hull.ipynb")
    env = installs.get("student")
    probe = env.run("python", "-c", "import reference", cwd=course)
    assert probe.returncode != 0, "the student's install must not contain the model solutions"
    proc = env.run("autograder", "check", "hull/hull.ipynb", cwd=course)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "PASS" in proc.stdout and "FAIL" not in proc.stdout


def test_gradescope_zip_installed_by_its_own_setup_script(
        installs: Installs, expected: dict[str, dict[str, float]]) -> None:
    """setup.sh and run_autograder exactly as Gradescope runs them, under a fake /autograder."""
    root, env, names = installs.get("gradescope")
    assert "assignment/hull/hull.ipynb" in names
    bundled = (root / "source" / "assignment" / "hull" / "hull.ipynb").read_text()
    assert "### BEGIN SOLUTION" not in bundled, "the zip must not hold the instructor notebook"
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


def test_ordinary_user_installed_package_assignment_outside(
        repo: Path, workspace: Path, installs: Installs, expected: dict[str, dict[str, float]]) -> None:
    """``pip install .`` (not editable) by an ordinary user with Debian's Python 3.11, the
    assignment folder given by its path, outside any checkout.

    Run as root, the test creates the user; otherwise it runs as the current user
    (still not root) with this interpreter.
    """
    made = installs.get("user")
    if isinstance(made, str):
        pytest.skip(made)
    env, _ = made
    probe = env.run("python", "-c", "import os, autograder; print(os.geteuid(), autograder.__file__)",
                    cwd=workspace)
    assert probe.returncode == 0 and not probe.stdout.startswith("0 "), probe.stdout + probe.stderr
    assert "site-packages" in probe.stdout  # the installed copy, not the checkout
    course = workspace / "user-course"
    shutil.copytree(repo / "assignments" / "hull", course / "hull",
                    ignore=shutil.ignore_patterns("examples"))
    envs._open_up(course)
    assert grade_with(env, str(course / "hull"), course, cwd=course) == expected


def test_ordinary_user_long_batch_grades_every_copy_alike(
        workspace: Path, installs: Installs, expected: dict[str, dict[str, float]]) -> None:
    """A batch long enough for the warm parent to move its heap into huge pages (after
    ``hugepages.COLLAPSE_AFTER`` children), graded by an ordinary user on one slot: every
    copy of an example gets the developer's scores, before the move and after it."""
    from autograder.worker import hugepages

    made = installs.get("user")
    if isinstance(made, str):
        pytest.skip(made)
    env, _ = made
    course = workspace / "user-long-batch"
    shutil.copytree(ROOT / "assignments" / "hull", course / "hull",
                    ignore=shutil.ignore_patterns("examples"))
    envs._open_up(course)
    copies = hugepages.COLLAPSE_AFTER // len(GRADED) + 3
    out = course / "results"
    out.mkdir()
    if env.user is not None:
        shutil.chown(out, env.user, env.user)
    proc = env.run("autograder", "grade", str(course / "hull"),
                   *submissions(course / "in", copies), "--out", str(out), "--jobs", "1",
                   "--no-progress", cwd=course)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    found = scores(out)
    assert len(found) == copies * len(GRADED)
    for student, checks in found.items():
        assert checks == expected[student.rsplit("-", 1)[0]], student
