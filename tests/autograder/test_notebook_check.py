"""``from autograder import check; check()`` inside the released notebook (issue 27 point 5):
the public checks on the notebook as saved, through ``autograder check``'s sandbox, shown as
an HTML table in the cell's output; ``check("convex_hull")`` shows that function's checks."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest

from autograder import api

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow


def released(tmp_path: Path, example: str, *cells: str, assignment: str = "hull") -> Path:
    """The release of ``assignment`` with ``example``'s answers saved as the student's
    notebook, then ``cells`` appended (what the student types at the end)."""
    folder = tmp_path / assignment
    api.release(assignment, out=folder)
    nb = nbformat.read(ROOT / "assignments" / assignment / "examples" / f"{example}.ipynb",
                       as_version=4)
    nb.cells += [nbformat.v4.new_code_cell(c) for c in cells]
    nbformat.write(nb, folder / f"{assignment}.ipynb")
    return folder


def run(folder: Path, monkeypatch: pytest.MonkeyPatch) -> list[nbformat.NotebookNode]:
    """Execute the notebook as Jupyter does (kernel started in its folder); its cells."""
    import nbclient

    monkeypatch.setenv("PYTHONPATH", str(ROOT))  # the kernel imports this checkout's numgrade
    monkeypatch.delenv("JPY_SESSION_NAME", raising=False)
    nb = nbformat.read(folder / f"{folder.name}.ipynb", as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(folder)}}).execute()
    return nb.cells


def html_of(cell: nbformat.NotebookNode) -> str:
    return "".join(o.get("data", {}).get("text/html", "") for o in cell.outputs
                   if o.output_type in ("execute_result", "display_data"))


def test_check_in_the_notebook_shows_the_public_checks_as_a_table(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = released(tmp_path, "solution", "from autograder import check\ncheck()",
                      "check('convex_hull')")
    every, one = (html_of(c) for c in run(folder, monkeypatch)[-2:])
    expected = api.check(folder / "hull.ipynb", assignment=folder)  # what `autograder check` says
    names = [t.name for t in expected.tests]
    assert names and not any(t.hidden for t in expected.tests)
    assert "<table" in every and f"{expected.score:g}/{expected.max_score:g} points" in every
    assert all(name in every for name in names)
    assert "autograder.student" not in every and "NameError" not in every  # check() cells: no-ops when graded
    assert "Hidden checks run when your notebook is graded" in every
    convex = [n for n in names if n.startswith("convex_hull")]
    assert convex and all(n in one for n in convex)
    assert not any(n in one for n in names if n.startswith("orientation"))


def test_check_in_the_notebook_reports_what_is_wrong_with_the_pictures(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """bezier's public checks attach a picture of the student's curve when it is wrong."""
    folder = released(tmp_path, "wrong-split-reversed", "import autograder\nautograder.check()",
                      assignment="bezier")
    page = html_of(run(folder, monkeypatch)[-1])
    expected = api.check(folder / "bezier.ipynb", assignment=folder, out_dir=tmp_path / "result")
    assert expected.score < expected.max_score
    assert f"{expected.score:g}/{expected.max_score:g} points" in page
    assert 'class="numgrade-failed"' in page or 'class="numgrade-partial"' in page
    attached = sum(len(t.attachments) for t in expected.tests)
    assert attached and page.count("data:image/png;base64,") == attached  # the pictures, inline


def test_check_of_an_unknown_function_says_which_exist(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    folder = released(tmp_path, "solution", "from autograder import check\ncheck('convex_hul')")
    import nbclient

    with pytest.raises(nbclient.exceptions.CellExecutionError) as raised:
        run(folder, monkeypatch)
    assert "No public check is about 'convex_hul'" in str(raised.value)
    assert "convex_hull_small" in str(raised.value)


def test_nothing_hidden_is_in_the_release_the_kernel_checks_from(tmp_path: Path) -> None:
    """The kernel's check() can only reach the release: no hidden check, no instructor notebook."""
    folder = released(tmp_path, "solution")
    files = [p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()]
    assert not any("hidden" in f or f.startswith(("reference", "examples")) for f in files), files
    hidden = {p.name for p in (ROOT / "assignments" / "hull" / "checks" / "hidden").glob("*.py")}
    assert hidden and not hidden & {Path(f).name for f in files}


def test_the_release_says_where_submit_sends(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from autograder.errors import UsageError
    from autograder.student import inline

    notebook = api.release("hull", out=tmp_path / "hull", server="https://grader.example.edu")
    assert nbformat.read(notebook, as_version=4).metadata["numgrade"]["server"] == \
        "https://grader.example.edu"
    monkeypatch.delenv("AUTOGRADER_SERVER", raising=False)
    assert inline._metadata_server(notebook) == "https://grader.example.edu"
    with pytest.raises(UsageError, match="address of the course's service"):
        api.release("hull", out=tmp_path / "again", server="grader.example.edu")
