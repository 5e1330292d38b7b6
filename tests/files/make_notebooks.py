"""Write the small problem notebooks under ``tests/files/notebooks/``.

Run ``python tests/files/make_notebooks.py`` after changing this script; the
written files are committed so the tests never depend on it. Each file and the
outcome it must get is listed in ``tests/files/notebooks/README.md``.
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

HERE = Path(__file__).resolve().parent / "notebooks"

PYTHON_KERNEL = {
    "kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
    "language_info": {"name": "python"},
}


def _ids(nb: nbformat.NotebookNode, stem: str) -> nbformat.NotebookNode:
    """Give cells stable ids so regenerating produces identical files."""
    for number, cell in enumerate(nb.cells):
        cell["id"] = f"{stem}-{number}"
    return nb


def _write(name: str, nb: nbformat.NotebookNode) -> None:
    nbformat.write(_ids(nb, Path(name).stem), HERE / name)


def magics() -> nbformat.NotebookNode:
    """IPython syntax everywhere: must parse and run."""
    return new_notebook(metadata=PYTHON_KERNEL, cells=[
        new_markdown_cell("# Magics\nIPython syntax must not break grading."),
        new_code_cell("%matplotlib inline\nimport numpy as np\nimport matplotlib.pyplot as plt"),
        new_code_cell("%time total = sum(range(10))\n!ls\nfiles = !ls"),
        new_code_cell("%%time\ndef convex_hull(points):\n    return np.asarray(points)[:3]"),
        new_code_cell("from IPython.display import display\ndisplay(convex_hull([[0, 0], [1, 0], [0, 1]]))\nnp.zeros?"),
    ])


def no_code() -> nbformat.NotebookNode:
    """Only markdown and a blank code cell: graded as empty (zero cells)."""
    return new_notebook(metadata=PYTHON_KERNEL, cells=[
        new_markdown_cell("# My answers\nI wrote everything in markdown."),
        new_code_cell("   \n"),
    ])


def julia() -> nbformat.NotebookNode:
    """A Julia notebook: rejected with kind ``language``."""
    return new_notebook(
        metadata={"kernelspec": {"display_name": "Julia 1.9.3", "language": "julia",
                                 "name": "julia-1.9"},
                  "language_info": {"name": "julia"}},
        cells=[new_code_cell("function convex_hull(points)\n    points\nend")])


def minor_schema() -> nbformat.NotebookNode:
    """Bad metadata types and a damaged output: graded with a warning."""
    nb = new_notebook(metadata=PYTHON_KERNEL, cells=[
        new_code_cell("def double(x):\n    return 2 * x",
                      outputs=[new_output("stream", name="stdout", text="hi\n")]),
    ])
    nb.cells[0].metadata["collapsed"] = "yes"  # must be a boolean
    nb.cells[0].outputs[0]["name"] = 3  # must be a string: dropped anyway
    return nb


def nbformat3() -> dict:
    """A real format-3 notebook (worksheets): upgraded silently and graded."""
    return {
        "metadata": {"name": "", "signature": ""},
        "nbformat": 3,
        "nbformat_minor": 0,
        "worksheets": [{"metadata": {}, "cells": [
            {"cell_type": "heading", "level": 1, "metadata": {}, "source": ["Old notebook"]},
            {"cell_type": "code", "collapsed": False, "input": ["def double(x):\n", "    return 2 * x"],
             "language": "python", "metadata": {}, "outputs": [], "prompt_number": 1},
            {"cell_type": "markdown", "metadata": {}, "source": ["Some text."]},
            {"cell_type": "code", "collapsed": False, "input": ["print(double(21))"],
             "language": "python", "metadata": {},
             "outputs": [{"output_type": "stream", "stream": "stdout", "text": ["42\n"]}],
             "prompt_number": 2},
        ]}],
    }


def nbformat2() -> dict:
    """Format 2: too old, kind ``old-format``."""
    return {"metadata": {"name": "ancient"}, "nbformat": 2, "worksheets": [{"cells": []}]}


def bad_cell() -> dict:
    """A code cell whose source is a number: kind ``invalid``."""
    nb = json.loads(nbformat.writes(_ids(new_notebook(metadata=PYTHON_KERNEL, cells=[
        new_code_cell("x = 1")]), "bad-cell")))
    nb["cells"][0]["source"] = 42
    return nb


def main() -> None:
    HERE.mkdir(parents=True, exist_ok=True)
    _write("magics.ipynb", magics())
    _write("no-code.ipynb", no_code())
    _write("julia.ipynb", julia())
    _write("minor-schema.ipynb", minor_schema())
    (HERE / "nbformat3.ipynb").write_text(json.dumps(nbformat3(), indent=1) + "\n")
    (HERE / "nbformat2.ipynb").write_text(json.dumps(nbformat2(), indent=1) + "\n")
    (HERE / "bad-cell.ipynb").write_text(json.dumps(bad_cell(), indent=1) + "\n")
    (HERE / "empty-list.ipynb").write_text("[]\n")
    (HERE / "not-json.ipynb").write_text('{\n "cells": [\n  {"cell_type": "code",\n   "source": "x = 1"\n  }\n')
    (HERE / "binary.ipynb").write_bytes(b"\x00" + random.Random(20240).randbytes(2047))
    latin1 = nbformat.writes(_ids(new_notebook(metadata=PYTHON_KERNEL, cells=[
        new_code_cell("# Größe der Hülle\nn = 3")]), "latin1"))
    (HERE / "latin1.ipynb").write_bytes(latin1.encode("latin-1"))


if __name__ == "__main__":
    main()
