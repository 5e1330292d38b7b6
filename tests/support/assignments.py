"""A small assignment written from scratch: one solution cell ``double(x)`` and the checks given."""

from __future__ import annotations

from pathlib import Path

import nbformat

RIGHT = "def double(x):\n    return 2 * x\n"
#: a public check of ``double``, for ``write_double``'s ``checks``
CHECK = ("def test_double(student):\n"
         "    assert student.double(21) == 42, 'double(21) must be 42'\n")


def write_double(root: Path, name: str, checks: dict[str, str]) -> Path:
    """``root/name``: an assignment whose notebook defines ``double``; ``checks`` maps file
    names in ``checks/public`` to their text. Returns the folder."""
    folder = root / name
    (folder / "checks" / "public").mkdir(parents=True)
    (folder / "checks" / "hidden").mkdir(parents=True)
    (folder / "assignment.toml").write_text(
        f'[assignment]\nname = "{name}"\ntitle = "Double it"\nnotebook = "{name}.ipynb"\n')
    cell = nbformat.v4.new_code_cell(
        "### BEGIN SOLUTION\n" + RIGHT + "### END SOLUTION",
        metadata={"nbgrader": {"grade_id": "double", "solution": True, "grade": False,
                               "locked": False, "schema_version": 3}})
    nbformat.write(nbformat.v4.new_notebook(cells=[cell]), folder / f"{name}.ipynb")
    for filename, text in checks.items():
        (folder / "checks" / "public" / filename).write_text(text)
    return folder


def submission(folder: Path, name: str, code: str) -> Path:
    """``folder/name.ipynb``: a notebook of one code cell, ``code``."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}.ipynb"
    nbformat.write(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)]), path)
    return path
