"""Reading submitted notebooks: every problem file gets its documented outcome."""

from __future__ import annotations

import json
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

from autograder.engine.notebook import (
    EMPTY_NOTEBOOK_MESSAGE,
    ERROR_KINDS,
    MAX_CODE_BYTES,
    MAX_NOTEBOOK_BYTES,
    Cell,
    Notebook,
    code_sources,
    parse_notebook,
    read_notebook,
)
from autograder.engine.staticscan import scan
from autograder.errors import NotebookError

FILES = Path(__file__).resolve().parents[1] / "files" / "notebooks"

REJECTED = {
    "not-json.ipynb": "not-json",
    "binary.ipynb": "binary",
    "latin1.ipynb": "encoding",
    "empty-list.ipynb": "not-notebook",
    "nbformat2.ipynb": "old-format",
    "bad-cell.ipynb": "invalid",
    "julia.ipynb": "language",
}
GRADED = ("no-code.ipynb", "nbformat3.ipynb", "minor-schema.ipynb", "magics.ipynb")


def _write(path: Path, nb: nbformat.NotebookNode) -> Path:
    nbformat.write(nb, str(path))
    return path


def _python(cells: list) -> nbformat.NotebookNode:
    return new_notebook(cells=cells, metadata={
        "kernelspec": {"name": "python3", "language": "python", "display_name": "Python 3"}})


def test_every_problem_file_is_listed_in_the_readme() -> None:
    readme = (FILES / "README.md").read_text()
    for path in FILES.glob("*.ipynb"):
        assert f"`{path.name}`" in readme, path.name
    assert set(REJECTED) | set(GRADED) == {p.name for p in FILES.glob("*.ipynb")}


@pytest.mark.parametrize("name, kind", sorted(REJECTED.items()))
def test_problem_file_is_rejected_with_its_kind(name: str, kind: str) -> None:
    with pytest.raises(NotebookError) as info:
        read_notebook(FILES / name)
    assert info.value.kind == kind
    assert kind in ERROR_KINDS
    message = str(info.value)
    assert "Traceback" not in message and len(message) < 400
    assert any(word in message for word in ("submit", "Submit", "save")), message
    with pytest.raises(NotebookError) as from_bytes:  # an upload's bytes: the same answer
        parse_notebook((FILES / name).read_bytes())
    assert from_bytes.value.kind == kind and str(from_bytes.value) == message


@pytest.mark.parametrize("name", GRADED)
def test_problem_file_is_graded(name: str) -> None:
    nb = read_notebook(FILES / name)
    assert isinstance(nb, Notebook) and nb.language == "python"
    assert nb.path == FILES / name
    assert len(nb.sha256) == 64
    uploaded = parse_notebook((FILES / name).read_bytes(), path="upload.ipynb")
    assert [(c.index, c.source) for c in uploaded.cells] == [(c.index, c.source) for c in nb.cells]
    assert (uploaded.sha256, uploaded.warnings) == (nb.sha256, nb.warnings)
    assert uploaded.path == Path("upload.ipynb")


def test_not_json_gives_line_and_column() -> None:
    with pytest.raises(NotebookError, match=r"line 6, column 1"):
        read_notebook(FILES / "not-json.ipynb")


def test_julia_message_names_the_language() -> None:
    with pytest.raises(NotebookError, match="This notebook runs Julia, but the assignment "
                                            "needs a Python 3 notebook."):
        read_notebook(FILES / "julia.ipynb")


def test_no_code_is_an_empty_notebook_not_an_error() -> None:
    nb = read_notebook(FILES / "no-code.ipynb")
    assert nb.cells == () and nb.is_empty
    assert code_sources(nb) == []
    assert "no code" in EMPTY_NOTEBOOK_MESSAGE


def test_nbformat3_is_upgraded() -> None:
    nb = read_notebook(FILES / "nbformat3.ipynb")
    assert nb.nbformat == 3
    assert [c.index for c in nb.cells] == [1, 3]
    assert code_sources(nb) == ["def double(x):\n    return 2 * x", "print(double(21))"]


def test_minor_schema_problems_become_a_warning() -> None:
    nb = read_notebook(FILES / "minor-schema.ipynb")
    assert len(nb.warnings) == 1
    assert "collapsed" in nb.warnings[0] and "graded anyway" in nb.warnings[0]
    assert code_sources(nb) == ["def double(x):\n    return 2 * x"]


def test_magics_cells_are_kept_and_scannable() -> None:
    nb = read_notebook(FILES / "magics.ipynb")
    assert len(nb.cells) == 4 and nb.cells[0].source.startswith("%matplotlib inline")
    report = scan(code_sources(nb), ["scipy.spatial"])
    assert report.errors == () and report.uses == () and report.dynamic == ()


def test_cells_record_index_ids_and_grade_ids(tmp_path: Path) -> None:
    nb = _python([new_markdown_cell("# Title"), new_code_cell("x = 1"),
                  new_code_cell(""), new_code_cell("y = 2")])
    nb.cells[1]["id"] = "first"
    nb.cells[3].metadata["nbgrader"] = {"grade_id": "answer", "solution": True}
    read = read_notebook(_write(tmp_path / "ids.ipynb", nb))
    assert read.cells == (Cell(index=1, source="x = 1", cell_id="first"),
                          Cell(index=3, source="y = 2", cell_id=nb.cells[3]["id"],
                               grade_id="answer"))
    assert read.warnings == () and read.nbformat == 4


def test_list_sources_are_joined_and_bom_is_accepted(tmp_path: Path) -> None:
    document = json.loads(nbformat.writes(_python([new_code_cell("a = 1\nb = 2")])))
    document["cells"][0]["source"] = ["a = 1\n", "b = 2"]
    path = tmp_path / "bom.ipynb"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(document).encode())
    assert code_sources(read_notebook(path)) == ["a = 1\nb = 2"]


def test_notebook_without_language_metadata_is_taken_as_python(tmp_path: Path) -> None:
    path = _write(tmp_path / "bare.ipynb", new_notebook(cells=[new_code_cell("x = 1")]))
    assert read_notebook(path).language == "python"


def test_huge_outputs_are_rejected_before_reading(tmp_path: Path) -> None:
    """~50 MB of outputs: over the default limit, so ``too-large``, not a memory spike."""
    blob = "x" * (1 << 20)
    outputs = [new_output("stream", name="stdout", text=blob) for _ in range(50)]
    path = _write(tmp_path / "huge-outputs.ipynb",
                  _python([new_code_cell("print('x' * 2**20)", outputs=outputs)]))
    assert path.stat().st_size > MAX_NOTEBOOK_BYTES
    with pytest.raises(NotebookError) as info:
        read_notebook(path)
    assert info.value.kind == "too-large"
    assert "Clear all outputs (Kernel > Restart & Clear Output) and submit again." in str(info.value)


def test_large_outputs_under_the_limit_are_dropped_and_graded(tmp_path: Path) -> None:
    outputs = [new_output("stream", name="stdout", text="y" * (1 << 20)) for _ in range(5)]
    path = _write(tmp_path / "big-outputs.ipynb",
                  _python([new_code_cell("print('y')", outputs=outputs)]))
    nb = read_notebook(path)
    assert code_sources(nb) == ["print('y')"] and nb.warnings == ()


def test_limits_are_keyword_arguments(tmp_path: Path) -> None:
    path = _write(tmp_path / "small.ipynb", _python([new_code_cell("x = 1" * 100)]))
    with pytest.raises(NotebookError) as info:
        read_notebook(path, max_bytes=100)
    assert info.value.kind == "too-large"
    with pytest.raises(NotebookError, match="load it from a file") as info:
        read_notebook(path, max_code_bytes=10)
    assert info.value.kind == "too-large"


def test_too_much_code_is_rejected(tmp_path: Path) -> None:
    code = "data = [" + "1, " * (MAX_CODE_BYTES // 3 + 10) + "]"
    path = _write(tmp_path / "big-code.ipynb", _python([new_code_cell(code)]))
    with pytest.raises(NotebookError) as info:
        read_notebook(path)
    assert info.value.kind == "too-large"


@pytest.mark.parametrize("content, kind", [
    (b"", "not-json"),
    (b"{\"cells\": [], \"nbformat\": 4", "not-json"),
    (b"[" * 100_000, "not-json"),
    (b"\"just a string\"", "not-notebook"),
    (b"{\"metadata\": {}}", "not-notebook"),
    (b"{\"cells\": [], \"nbformat\": \"four\"}", "not-notebook"),
    (b"{\"cells\": {}, \"nbformat\": 4}", "invalid"),
    (b"{\"cells\": [3], \"nbformat\": 4}", "invalid"),
    (b"{\"cells\": [], \"nbformat\": 5}", "invalid"),
    (b"{\"worksheets\": [{\"cells\": 7}], \"nbformat\": 3}", "invalid"),
    (b"\xff\xfe{\x00}\x00", "encoding"),
    (b"PK\x03\x04rest-of-a-zip", "binary"),
    (b"%PDF-1.7", "binary"),
], ids=lambda value: value[:24].decode("latin-1") if isinstance(value, bytes) else value)
def test_malformed_content(tmp_path: Path, content: bytes, kind: str) -> None:
    path = tmp_path / "sub.ipynb"
    path.write_bytes(content)
    with pytest.raises(NotebookError) as info:
        read_notebook(path)
    assert info.value.kind == kind, str(info.value)


def test_missing_file_and_directory_are_unreadable(tmp_path: Path) -> None:
    for path in (tmp_path / "missing.ipynb", tmp_path):
        with pytest.raises(NotebookError) as info:
            read_notebook(path)
        assert info.value.kind == "unreadable"


def test_r_kernel_is_rejected(tmp_path: Path) -> None:
    nb = new_notebook(cells=[new_code_cell("x <- 1")],
                      metadata={"kernelspec": {"name": "ir", "display_name": "R"}})
    with pytest.raises(NotebookError, match="runs R,") as info:
        read_notebook(_write(tmp_path / "r.ipynb", nb))
    assert info.value.kind == "language"


def test_sha256_is_of_the_raw_bytes(tmp_path: Path) -> None:
    import hashlib

    path = _write(tmp_path / "a.ipynb", _python([new_code_cell("x = 1")]))
    assert read_notebook(path).sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
