"""The released template kept on disk: equal to nbgrader's passes, never stale, never required."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbgrader import preprocessors

from autograder.engine import identify
from autograder.engine.released import cache_folder, released_notebook

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"


def _passes(path: Path) -> nbformat.NotebookNode:
    nb, resources = nbformat.read(path, as_version=4), {}
    for name in ("ClearSolutions", "ClearHiddenTests", "ClearMarkScheme"):
        nb, resources = getattr(preprocessors, name)().preprocess(nb, resources)
    return nb


def _code(nb: nbformat.NotebookNode) -> list[str]:
    return [c.source for c in nb.cells if c.cell_type == "code"]


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("NUMGRADE_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache" / "released"


def test_the_kept_template_is_nbgraders_and_is_used_without_importing_nbgrader(
        cache: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert cache_folder() == cache
    first = released_notebook(HULL / "hull.ipynb")
    assert _code(first) == _code(_passes(HULL / "hull.ipynb"))
    assert "BEGIN SOLUTION" not in "".join(_code(first))
    assert len(list(cache.glob("*.ipynb"))) == 1
    # a second read comes from the file: nbgrader cannot even be imported now
    monkeypatch.setitem(sys.modules, "nbgrader", None)
    assert _code(released_notebook(HULL / "hull.ipynb")) == _code(first)


def test_a_changed_notebook_gets_its_own_template(cache: Path, tmp_path: Path) -> None:
    copy = tmp_path / "hull.ipynb"
    copy.write_bytes((HULL / "hull.ipynb").read_bytes())
    before = _code(released_notebook(copy))
    nb = nbformat.read(copy, as_version=4)
    answer = next(c for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("solution"))
    answer.source = "# a new stub the students get\n" + answer.source
    nbformat.write(nb, copy)
    after = _code(released_notebook(copy))
    assert after != before and any("a new stub the students get" in s for s in after)
    assert len(list(cache.glob("*.ipynb"))) == 2


def test_an_unwritable_or_damaged_cache_only_costs_time(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the cache folder would be")
    monkeypatch.setenv("NUMGRADE_CACHE_DIR", str(blocked))
    expected = _code(_passes(HULL / "hull.ipynb"))
    assert _code(released_notebook(HULL / "hull.ipynb")) == expected
    monkeypatch.setenv("NUMGRADE_CACHE_DIR", str(tmp_path / "cache"))
    released_notebook(HULL / "hull.ipynb")
    (entry,) = (tmp_path / "cache" / "released").glob("*.ipynb")
    entry.write_text("{ not json")
    assert _code(released_notebook(HULL / "hull.ipynb")) == expected
    assert nbformat.read(entry, as_version=4)  # and the damaged entry was written again


def test_an_untouched_template_is_still_flagged_from_the_kept_template(cache: Path) -> None:
    template = nbformat.reads(nbformat.writes(_passes(HULL / "hull.ipynb")), as_version=4)
    released_notebook(HULL / "hull.ipynb")  # the entry exists: the flag comes from it
    identify._fingerprint.cache_clear()
    from autograder.engine.assignment import load_assignment
    from autograder.engine.notebook import read_notebook

    path = cache.parent / "hull.ipynb"
    nbformat.write(template, path)
    found = identify.identify(read_notebook(path), load_assignment(HULL))
    assert any("released template of hull, unchanged" in n for n in found.notes)


def test_a_second_grading_run_does_not_import_nbgrader(tmp_path: Path) -> None:
    """The end to end reason for the cache: nbgrader's import (about 0.85 s) leaves the
    path to the first result once the template is kept."""
    env = {"NUMGRADE_CACHE_DIR": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin",
           "HOME": str(tmp_path)}
    imported = []
    for run in ("first", "second"):
        done = subprocess.run([sys.executable, "-X", "importtime", "-m", "autograder", "grade", "hull",
                               str(HULL / "examples" / "solution.ipynb"), "--out", str(tmp_path / run),
                               "--no-progress"], capture_output=True, text=True, env=env, cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-2000:]
        imported.append({line.split("|")[-1].strip() for line in done.stderr.splitlines()
                         if line.startswith("import time:")})
    assert "nbgrader" in imported[0] and "nbgrader" not in imported[1]
    scores = [(tmp_path / run / "grades.csv").read_text() for run in ("first", "second")]
    assert scores[0] == scores[1]
