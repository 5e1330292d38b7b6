"""Fixtures shared by the engine's end-to-end tests, built once per test session.

The ordinary user's venv (Debian's Python, numgrade installed non-editable) took about
two minutes to build, and four test modules each built their own; one session-scoped
build serves them all. It lies in the user's home, as a person makes it, which is also
the ordinary-user layout of test_layouts.py. The other layouts that test where a venv
lies (test_layouts.py) still build theirs, since the venv's location is what they test.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from tests.support import envs
from tests.support.examples import ExamplesBatch, release_and_grade


@pytest.fixture(scope="session")
def ordinary_user_venv() -> Iterator[tuple[envs.Env, Path]]:
    """Debian's Python in a venv of an ordinary user, numgrade installed non-editable; and
    the user's own copy of the repository (the checkout may be unreadable to the user, as
    under root's mode-700 home or a mktemp folder)."""
    why = envs.can_switch_users()
    if why is not None:
        pytest.skip(f"the ordinary-user tests cannot run: {why}")
    if not Path("/usr/bin/python3").exists():
        pytest.skip("the ordinary-user tests need Debian's /usr/bin/python3")
    user = envs.ordinary_user()
    top = envs.shared_tempdir("numgrade-user-venv-")
    # in the user's home, under a name of this session's own (another run may build one too)
    venv = Path(tempfile.mkdtemp(prefix="numgrade-venv-", dir=envs.home(user)))
    try:
        source = envs.copy_repository(top / "src")
        envs.give_to(user, top)  # the user builds in src
        envs.give_to(user, venv)  # and creates the venv
        venv.chmod(0o755)
        install = [str(source)] + ([str(source / "reference")]
                                   if (source / "reference" / "pyproject.toml").exists() else [])
        env = envs.make_venv(venv, install=install, python="/usr/bin/python3", user=user)
        yield env, source
    finally:
        shutil.rmtree(top, ignore_errors=True)
        shutil.rmtree(venv, ignore_errors=True)


@pytest.fixture(scope="session")
def examples_batch(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], ExamplesBatch]:
    """``examples_batch(name)``: the shipped assignment ``name`` released and its examples
    graded under several student folders (tests/support/examples.py), once a session.

    test_assignments.py (every copy in its band, the template at zero) and
    test_unseen_stability.py (one score per example under every seed) read the same
    batch: each used to grade the examples on its own.
    """
    made: dict[str, ExamplesBatch] = {}

    def batch(name: str) -> ExamplesBatch:
        if name not in made:
            made[name] = release_and_grade(name, tmp_path_factory.mktemp(f"examples-{name}"))
        return made[name]

    return batch
