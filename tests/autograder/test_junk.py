"""Stubs and junk earn nothing (issue 8.7), end to end through the real CLI.

For every shipped assignment, notebooks are made from the released template
(``autograder release``) with every graded function replaced by a stub: a
constant (``return 0``, ``return [0, 1, 2]``, ``return np.zeros(...)``,
``return None``), random answers, functions that return a constant or random
values (for a function that returns a function, such as approximation's
``make_interpolant``), one that samples the functions it is given exactly as the
rules ask and then returns a constant, and the template itself. Each is graded with
``autograder grade`` and must score 0 on every check, so 0 per function and 0
in total: a degenerate case (collinear points, one pin, degree 0) earns credit
only for a function that also gets the general cases of its family right.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[2]
ASSIGNMENTS = sorted(p.parent.name for p in (ROOT / "assignments").glob("*/assignment.toml"))

pytestmark = pytest.mark.slow

#: name -> the body of every stub (the stub takes ``*args, **kwargs``)
STUBS = {
    "return-zero": "return 0",
    "return-list": "return [0, 1, 2]",
    "return-zeros": ("first = np.asarray(args[0], dtype=float) if args else np.zeros(3)\n"
                     "    return np.zeros(first.shape if first.ndim else 3)"),
    "return-none": "return None",
    "random": ("rng = np.random.default_rng(len(repr(args)))\n"
               "    first = np.asarray(args[0], dtype=float) if args else np.zeros(3)\n"
               "    if first.ndim == 0:\n"
               "        return float(rng.normal())\n"
               "    if first.ndim == 2 and first.shape[1] == 2 and len(first) > 3:\n"
               "        return rng.choice(len(first), size=(max(1, len(first) // 3), 3))\n"
               "    return rng.normal(size=first.shape)"),
    "random-indices": ("rng = np.random.default_rng(len(repr(args)))\n"
                       "    n = len(args[0]) if args and hasattr(args[0], '__len__') else 3\n"
                       "    return rng.permutation(n)[:max(1, min(n, 3))]"),
    # junk returned as a function (approximation's make_interpolant returns p(t))
    "constant-function": ("def p(t, *rest, **more):\n"
                          "        t = np.asarray(t, dtype=float)\n"
                          "        return 0.5 if t.ndim == 0 else np.full(t.shape, 0.5)\n"
                          "    return p"),
    "random-function": ("def p(t, *rest, **more):\n"
                        "        t = np.asarray(t, dtype=float)\n"
                        "        rng = np.random.default_rng(t.size)\n"
                        "        return float(rng.normal()) if t.ndim == 0 else "
                        "rng.normal(size=t.shape)\n"
                        "    return p"),
    # obeys every rule about sampling (each callable argument once, at the Chebyshev
    # nodes of the degree given) and returns a constant: sampling earns nothing alone
    "sampling-constant": ("n = next((a for a in args if isinstance(a, int)), 8)\n"
                          "    x = -np.cos(np.arange(n + 1) * np.pi / n)\n"
                          "    level = [float(np.mean(a(x))) for a in args if callable(a)]\n"
                          "    level = level[0] if level else 0.5\n"
                          "    def p(t, *rest, **more):\n"
                          "        t = np.asarray(t, dtype=float)\n"
                          "        return level if t.ndim == 0 else np.full(t.shape, level)\n"
                          "    if any(callable(a) for a in args) and len(args) >= 4:\n"
                          "        return p(args[3])  # interpolate(f, n, nodes, t)\n"
                          "    return p"),
}


def run(*args: str, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "autograder", *args], capture_output=True,
                          text=True, timeout=timeout)


def defined_functions(notebook: nbformat.NotebookNode) -> list[str]:
    names = []
    for cell in notebook.cells:
        if cell.cell_type != "code":
            continue
        try:
            tree = ast.parse(cell.source)
        except SyntaxError:
            continue
        names += [d.name for d in tree.body if isinstance(d, ast.FunctionDef)]
    return names


def graded_functions(name: str, notebook: nbformat.NotebookNode) -> list[str]:
    """The template's functions that the assignment's checks call (by name)."""
    checks = " ".join(p.read_text() for p in (ROOT / "assignments" / name / "checks")
                      .rglob("*.py"))
    words = set(re.findall(r"[A-Za-z_]\w*", checks))
    graded = [f for f in defined_functions(notebook) if f in words]
    assert graded, f"{name}: no function of the template is called by the checks"
    return graded


def with_stubs(notebook: nbformat.NotebookNode, functions: list[str], body: str
               ) -> nbformat.NotebookNode:
    copy = nbformat.from_dict(json.loads(json.dumps(notebook)))
    source = "import numpy as np\n\n" + "\n\n".join(
        f"def {f}(*args, **kwargs):\n    {body}\n" for f in functions)
    copy.cells.append(nbformat.v4.new_code_cell(source))
    return copy


@pytest.mark.parametrize("name", ASSIGNMENTS)
def test_stubs_and_template_score_zero(tmp_path: Path, name: str) -> None:
    released = run("release", name, "--out", str(tmp_path / "release"))
    assert released.returncode == 0, released.stderr
    template_path = next((tmp_path / "release").glob("*.ipynb"))
    template = nbformat.read(template_path, as_version=4)
    functions = graded_functions(name, template)
    submissions = tmp_path / "submitted"
    submissions.mkdir()
    nbformat.write(template, submissions / "template.ipynb")
    for stub, body in STUBS.items():
        nbformat.write(with_stubs(template, functions, body), submissions / f"{stub}.ipynb")
    proc = run("grade", name, str(submissions), "--out", str(tmp_path / "results"),
               "--jobs", "2", "--no-progress")
    assert proc.returncode == 0, proc.stderr[-3000:]
    earned = []
    for stub in ["template", *STUBS]:
        result = json.loads((tmp_path / "results" / stub / "results.json").read_text())
        assert result["extra_data"]["outcome"] != "error", f"{name}/{stub}: {result['output']}"
        assert result["max_score"] > 0
        earned += [f"{stub}: {t['name']} earned {t['score']} of {t['max_score']}"
                   for t in result["tests"] if t["score"] > 0]
    assert not earned, f"{name}: junk earned points ({functions}):\n" + "\n".join(earned)
