"""Fixtures shared by the engine's end-to-end tests, built once per test session.

The ordinary user's venv (Debian's Python, numgrade installed non-editable) took about
two minutes to build, and three test modules each built their own; one session-scoped
build serves them all. The layouts that test where a venv lies (test_layouts.py) still
build theirs, since the venv's location is what they test.
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support import envs


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
    try:
        source = envs.copy_repository(top / "src")
        envs.give_to(user, top)  # the user builds in src and creates the venv
        install = [str(source)] + ([str(source / "reference")]
                                   if (source / "reference" / "pyproject.toml").exists() else [])
        env = envs.make_venv(top / "venv", install=install, python="/usr/bin/python3", user=user)
        yield env, source
    finally:
        shutil.rmtree(top, ignore_errors=True)
