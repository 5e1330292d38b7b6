"""Loading assignment folders: the happy path and every mistake, with its message."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from autograder.engine.assignment import (
    Assignment,
    checks_digest,
    list_assignments,
    load_assignment,
)
from autograder.engine.forbidden import Rules
from autograder.errors import AssignmentError, UsageError

TOML = """\
[assignment]
name = "hull"
title = "Convex hull by Jarvis march"
notebook = "hull.ipynb"
data = ["data/*.npy"]

[rules]
forbid = ["scipy.spatial"]
reason = "Write Jarvis march yourself; scipy.spatial is not allowed here."

[limits]
notebook_timeout = 30
call_timeout = 2.5
memory_bytes = 1_000_000_000
cpu_seconds = 20.5
"""


def make_assignment(root: Path, name: str = "hull", toml: str | None = TOML, *,
                    files: dict[str, str] | None = None) -> Path:
    """An assignment folder ``root/assignments/<name>`` with a notebook, data and checks."""
    folder = root / "assignments" / name
    defaults = {
        "hull.ipynb": "{}",
        "data/points.npy": "not really numpy",
        "data/more.npy": "x",
        "data/readme.txt": "not matched by the glob",
        "checks/public/test_public.py": "def test_a():\n    pass\n",
        "checks/public/_helpers.py": "X = 1\n",
        "checks/hidden/test_hidden.py": "def test_b():\n    pass\n",
    }
    for relative, text in {**defaults, **(files or {})}.items():
        if text is None:
            continue
        path = folder / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    if toml is not None:
        (folder / "assignment.toml").write_text(textwrap.dedent(toml))
    return folder


def test_load_by_name(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path)
    a = load_assignment("hull", search_root=tmp_path)
    assert isinstance(a, Assignment)
    assert (a.name, a.title, a.root) == ("hull", "Convex hull by Jarvis march", folder.resolve())
    assert a.notebook == folder.resolve() / "hull.ipynb"
    assert [p.name for p in a.data_files] == ["more.npy", "points.npy"]
    assert all(p.is_absolute() for p in (*a.data_files, *a.public_checks, *a.hidden_checks))
    assert [p.name for p in a.public_checks] == ["test_public.py"]
    assert [p.name for p in a.hidden_checks] == ["test_hidden.py"]
    assert a.rules == Rules(forbid=("scipy.spatial",),
                            reason="Write Jarvis march yourself; scipy.spatial is not allowed here.")
    assert (a.notebook_timeout, a.call_timeout) == (30.0, 2.5)
    assert a.limits == (("cpu_seconds", 20.5), ("memory_bytes", 1_000_000_000))
    assert len(a.checks_digest) == 64


def test_load_by_path_and_by_toml_path(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path)
    assert load_assignment(folder).root == folder.resolve()
    assert load_assignment(str(folder)).root == folder.resolve()
    assert load_assignment(folder / "assignment.toml").root == folder.resolve()


def test_search_root_may_be_the_assignments_folder_itself(tmp_path: Path) -> None:
    make_assignment(tmp_path)
    assert load_assignment("hull", search_root=tmp_path / "assignments").name == "hull"


def test_defaults_for_a_minimal_toml(tmp_path: Path) -> None:
    make_assignment(tmp_path, toml="")
    a = load_assignment("hull", search_root=tmp_path)
    assert (a.name, a.title, a.notebook.name) == ("hull", "hull", "hull.ipynb")
    assert a.data_files == () and a.rules == Rules()
    assert (a.notebook_timeout, a.call_timeout, a.limits) == (60.0, 10.0, ())


def test_frozen(tmp_path: Path) -> None:
    make_assignment(tmp_path)
    a = load_assignment("hull", search_root=tmp_path)
    with pytest.raises(AttributeError):
        a.name = "other"  # type: ignore[misc]


def test_list_assignments(tmp_path: Path) -> None:
    make_assignment(tmp_path, "hull")
    make_assignment(tmp_path, "bezier", toml="")
    (tmp_path / "assignments" / "not-an-assignment").mkdir()
    assert list_assignments(tmp_path) == ["bezier", "hull"]
    assert list_assignments(tmp_path / "nowhere") == []


def test_unknown_name_lists_the_available_ones(tmp_path: Path) -> None:
    make_assignment(tmp_path, "hull")
    make_assignment(tmp_path, "bezier", toml="")
    with pytest.raises(AssignmentError, match=r"Unknown assignment 'hul'\. Did you mean 'hull'\?"
                                              r".*bezier, hull"):
        load_assignment("hul", search_root=tmp_path)


def test_errors_are_usage_errors(tmp_path: Path) -> None:
    with pytest.raises(UsageError):
        load_assignment("nothing", search_root=tmp_path)


def test_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(AssignmentError, match="does not exist"):
        load_assignment(tmp_path / "nowhere")


def test_missing_toml(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml=None)
    with pytest.raises(AssignmentError, match="has no assignment.toml"):
        load_assignment(folder)


def test_toml_syntax_error_gives_the_line(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml='[assignment]\ntitle = "unterminated\n')
    with pytest.raises(AssignmentError, match=r"TOML syntax error.*line 2"):
        load_assignment(folder)


def test_missing_notebook(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml='[assignment]\nnotebook = "other.ipynb"\n')
    with pytest.raises(AssignmentError, match=r"notebook 'other.ipynb' was not found"):
        load_assignment(folder)


def test_data_glob_matching_nothing(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml='[assignment]\ndata = ["data/*.csv"]\n')
    with pytest.raises(AssignmentError, match=r"data glob 'data/\*\.csv' matches no file"):
        load_assignment(folder)


@pytest.mark.parametrize("pattern", ["../*", "/etc/*", "checks/hidden/*.py"])
def test_data_glob_outside_or_into_checks(tmp_path: Path, pattern: str) -> None:
    folder = make_assignment(tmp_path, toml=f'[assignment]\ndata = ["{pattern}"]\n')
    with pytest.raises(AssignmentError, match="data glob"):
        load_assignment(folder)


def test_no_checks(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml="", files={})
    for path in (folder / "checks").rglob("test_*.py"):
        path.unlink()
    with pytest.raises(AssignmentError, match="has no checks"):
        load_assignment(folder)


def test_only_hidden_checks_is_enough(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml="")
    (folder / "checks" / "public" / "test_public.py").unlink()
    assert load_assignment(folder).public_checks == ()


@pytest.mark.parametrize("toml, words", [
    ("[assignment]\nnmae = 'hull'\n", ["unknown key(s) 'nmae' in [assignment]", "'name'"]),
    ("[rules]\nforbidden = []\n", ["unknown key(s) 'forbidden' in [rules]", "'forbid'"]),
    ("[limits]\ntimeout = 3\n", ["unknown key(s) 'timeout' in [limits]", "'call_timeout'"]),
    ("[grading]\nx = 1\n", ["unknown table(s) 'grading'", "'assignment'"]),
    ("rules = 3\n", ["'rules' must be a table"]),
])
def test_unknown_keys_name_the_allowed_ones(tmp_path: Path, toml: str, words: list[str]) -> None:
    folder = make_assignment(tmp_path, toml=toml)
    with pytest.raises(AssignmentError) as info:
        load_assignment(folder)
    for word in words:
        assert word in str(info.value)


@pytest.mark.parametrize("toml, match", [
    ("[assignment]\ntitle = 3\n", r"\[assignment\] title must be a string; got int 3"),
    ("[assignment]\ndata = 'data/*.npy'\n", r"\[assignment\] data must be a list"),
    ("[assignment]\ndata = [1]\n", r"data must be a list of non-empty strings"),
    ("[rules]\nforbid = 'scipy'\n", r"\[rules\] forbid must be a list"),
    ("[rules]\nforbid = ['scipy spatial']\n", r"must be a dotted name"),
    ("[rules]\nreason = false\n", r"\[rules\] reason must be a string"),
    ("[limits]\ncall_timeout = '10'\n", r"call_timeout must be a number"),
    ("[limits]\ncall_timeout = true\n", r"call_timeout must be a number"),
    ("[limits]\nnotebook_timeout = -1\n", r"notebook_timeout must be positive"),
    ("[limits]\nmemory_bytes = 1.5\n", r"memory_bytes must be an integer"),
    ("[assignment]\nname = 'bad name!'\n", r"name 'bad name!' must use only"),
])
def test_wrong_types(tmp_path: Path, toml: str, match: str) -> None:
    folder = make_assignment(tmp_path, toml=toml)
    with pytest.raises(AssignmentError, match=match):
        load_assignment(folder)


def test_messages_name_the_file(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml="[assignment]\ntitle = 3\n")
    with pytest.raises(AssignmentError, match=str(folder.resolve() / "assignment.toml")):
        load_assignment(folder)


def test_default_reason_names_the_forbidden_names(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, toml="[rules]\nforbid = ['scipy.spatial']\n")
    assert "scipy.spatial" in load_assignment(folder).rules.reason


def test_checks_digest_follows_checks_and_toml_only(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path)
    before = checks_digest(folder)
    assert load_assignment(folder).checks_digest == before
    (folder / "hull.ipynb").write_text('{"changed": true}')
    (folder / "checks" / "hidden" / "__pycache__").mkdir()
    (folder / "checks" / "hidden" / "__pycache__" / "x.pyc").write_bytes(b"cache")
    assert checks_digest(folder) == before
    (folder / "checks" / "hidden" / "test_hidden.py").write_text("def test_b():\n    assert 0\n")
    changed = checks_digest(folder)
    assert changed != before
    (folder / "assignment.toml").write_text(TOML + "\n# comment\n")
    assert checks_digest(folder) != changed


def test_name_from_toml_may_differ_from_the_folder(tmp_path: Path) -> None:
    folder = make_assignment(tmp_path, "copy-of-hull", toml='[assignment]\nname = "hull"\n')
    assert load_assignment(folder).name == "hull"
