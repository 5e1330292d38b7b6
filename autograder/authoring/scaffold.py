"""``autograder new NAME``: write a small, working assignment folder to start from.

The folder follows the layout of ``docs/design.md`` ("An assignment folder")
and passes ``autograder validate`` as written::

    NAME/
      assignment.toml
      NAME.ipynb                       instructor notebook (nbgrader format), one solution region
      data/samples.csv                 public data, copied next to the student's notebook
      checks/public/test_NAME_public.py
      checks/hidden/test_NAME_hidden.py
      examples/solution.ipynb          the instructor notebook itself
      examples/wrong-left-endpoints.ipynb   a typical wrong answer
      examples/expected.toml           the score band each example (and the template) must get

The example exercise is the composite trapezoid rule ``trapezoid(f, a, b, n)``:
it takes a function, so the hidden check shows how a check passes a function
it never releases and counts how often the student's code evaluates it. Edit
the notebook, the checks and the examples; keep ``validate`` passing.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from autograder.errors import UsageError

__all__ = ["new_assignment", "NAME_RULE"]

#: what an assignment name may be: it names a folder, a notebook and a Python module
NAME_RULE = re.compile(r"[a-z][a-z0-9_]{0,39}")

_METADATA = {"kernelspec": {"display_name": "Python 3", "language": "python", "name": "python3"},
             "language_info": {"name": "python", "version": "3.11"}}

_INTRO = """\
# {title}

The **composite trapezoid rule** approximates $\\int_a^b f(x)\\,dx$ with $n$ panels
of width $h = (b - a)/n$ and the nodes $x_j = a + jh$:

$$
T_n = h \\left( \\tfrac12 f(x_0) + f(x_1) + \\dots + f(x_{{n-1}}) + \\tfrac12 f(x_n) \\right).
$$

Write `trapezoid(f, a, b, n)`. `f` accepts a number or a numpy array: evaluate it
**once**, at the array of all $n + 1$ nodes.
"""

_IMPORTS = """\
import numpy as np

samples = np.loadtxt("data/samples.csv", delimiter=",")  # public data beside the notebook
"""

_SOLUTION = '''\
def trapezoid(f, a, b, n):
    """The composite trapezoid rule for the integral of f over [a, b] with n panels."""
    ### BEGIN SOLUTION
    x = np.linspace(a, b, n + 1)
    y = np.asarray(f(x), dtype=float)
    h = (b - a) / n
    return float(h * (y.sum() - 0.5 * (y[0] + y[-1])))
    ### END SOLUTION
'''

_TEST = """\
assert abs(trapezoid(lambda x: 2 * x, 0.0, 1.0, 4) - 1.0) < 1e-14, "exact for straight lines"
assert abs(trapezoid(np.sin, 0.0, np.pi, 100) - 2.0) < 1e-3
"""

_DEMO = """\
# the data: sample points of a curve, integrated with your rule through np.interp
print(trapezoid(lambda x: np.interp(x, samples[:, 0], samples[:, 1]), 0.0, 1.0, 50))
"""

_WRONG = '''\
def trapezoid(f, a, b, n):
    h = (b - a) / n
    # left endpoints only: a Riemann sum, not the trapezoid rule
    return float(sum(f(a + j * h) for j in range(n)) * h)
'''

_PUBLIC = '''\
"""Public checks for {name}: released to students (``autograder check {name}.ipynb``)."""

from __future__ import annotations

import numpy as np
import pytest

from autograder.checks import Student, expect_close


@pytest.mark.points(2)
def test_trapezoid_exp(student: Student) -> None:
    got = student.trapezoid(np.exp, 0.0, 1.0, 50)
    x = np.linspace(0.0, 1.0, 51)
    expected = 0.02 * (np.exp(x).sum() - 0.5 * (np.exp(0.0) + np.exp(1.0)))
    # the same sum in another order: rounding only (a Riemann sum misses by about 0.017)
    expect_close(got, expected, rtol=1e-12, atol=1e-14, name="trapezoid(exp, 0, 1, 50)")
'''

_HIDDEN = '''\
"""Hidden checks for {name}: never released. The function passed here stays in the grader."""

from __future__ import annotations

import numpy as np
import pytest

from autograder.engine.callbacks import traced
from autograder.checks import Credit, Student, expect_close


@pytest.mark.points(3)
def test_trapezoid_unseen_function(student: Student, credit: Credit) -> None:
    f = traced(lambda x: np.exp(-x) * np.cos(3 * x))
    got = student.trapezoid(f, -0.5, 1.5, 40)
    x = np.linspace(-0.5, 1.5, 41)
    y = f(x)  # calling the traced function from the check records nothing
    expected = 0.05 * (y.sum() - 0.5 * (y[0] + y[-1]))
    expect_close(got, expected, rtol=1e-12, atol=1e-14, name="trapezoid(f, -0.5, 1.5, 40)")
    if f.evaluations > 41:
        credit.partial(0.5, f"trapezoid evaluated f at {{f.evaluations}} points; the 41 nodes "
                            "are enough: evaluate f once, at the array of nodes.")
'''

_EXPECTED = """\
# The score band (fraction of the total, 0..1) each example must get, checked by
# `autograder validate {name}`; `contains` lists words its feedback must include.
# Total: 5 points (public 2, hidden 3).

[template]           # the released notebook, made by validate itself
min = 0
max = 0

[solution]
min = 1
max = 1

[wrong-left-endpoints]   # a Riemann sum: wrong values on both checks
min = 0
max = 0
contains = ["trapezoid"]
"""


def _markdown(grade_id: str, text: str) -> nbformat.NotebookNode:
    return new_markdown_cell(text, metadata={"nbgrader": {
        "grade": False, "grade_id": grade_id, "locked": True, "schema_version": 3,
        "solution": False, "task": False}})


def _code(grade_id: str, text: str, *, solution: bool = False,
          points: float | None = None) -> nbformat.NotebookNode:
    meta: dict[str, object] = {"grade": points is not None, "grade_id": grade_id,
                               "locked": not solution, "schema_version": 3,
                               "solution": solution, "task": False}
    if points is not None:
        meta["points"] = points
    return new_code_cell(text, metadata={"nbgrader": meta})


def _instructor(title: str) -> nbformat.NotebookNode:
    return new_notebook(metadata=_METADATA, cells=[
        _markdown("intro", _INTRO.format(title=title)),
        _code("imports", _IMPORTS),
        _code("trapezoid_solution", _SOLUTION, solution=True),
        _code("trapezoid_test", _TEST, points=1),
        _code("demo", _DEMO),
    ])


def _student(*sources: str) -> nbformat.NotebookNode:
    return new_notebook(metadata=_METADATA, cells=[new_code_cell(s) for s in sources])


def _toml(name: str, title: str) -> str:
    return "\n".join([
        "[assignment]",
        f"name = {json.dumps(name)}",
        f"title = {json.dumps(title)}",
        f"notebook = {json.dumps(name + '.ipynb')}",
        'data = ["data/*.csv"]',
        "",
        "[rules]                  # names the student's code may not use (an AST scan)",
        'forbid = ["scipy.integrate", "numpy.trapezoid", "numpy.trapz"]',
        'reason = "Write the trapezoid rule yourself: scipy.integrate and numpy.trapezoid '
        'do it for you."',
        "",
        "[limits]",
        "notebook_timeout = 60",
        "call_timeout = 10",
        "",
    ])


def new_assignment(name: str, *, out: Path, title: str | None = None) -> Path:
    """Write a working assignment folder ``out / name``; return its path.

    Parameters
    ----------
    name : str
        Lower-case letters, digits and underscores, starting with a letter: it
        names the folder, the notebook and the check modules.
    out : Path
        The folder to create it in (created if missing).
    title : str, optional
        The notebook's title (default: the name, capitalised).

    Raises
    ------
    UsageError
        The name breaks :data:`NAME_RULE`, or ``out / name`` already exists
        (nothing is ever overwritten).
    """
    if not NAME_RULE.fullmatch(name):
        raise UsageError(f"Assignment name {name!r} is not allowed: use lower-case letters, "
                         "digits and underscores, starting with a letter (at most 40), "
                         "e.g. 'quadrature' or 'newton_2'.")
    root = Path(out) / name
    if root.exists():
        raise UsageError(f"{root} already exists; choose another name or --out folder "
                         "(autograder new never overwrites).")
    title = title or f"{name.replace('_', ' ').capitalize()}: the trapezoid rule"
    for folder in ("data", "checks/public", "checks/hidden", "examples"):
        (root / folder).mkdir(parents=True)
    (root / "assignment.toml").write_text(_toml(name, title), encoding="utf-8")
    x = [j / 10 for j in range(11)]
    rows = [f"{v:.1f},{v * v:.2f}" for v in x]
    (root / "data" / "samples.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    (root / "checks" / "public" / f"test_{name}_public.py").write_text(
        _PUBLIC.format(name=name), encoding="utf-8")
    (root / "checks" / "hidden" / f"test_{name}_hidden.py").write_text(
        _HIDDEN.format(name=name), encoding="utf-8")
    nbformat.write(_instructor(title), str(root / f"{name}.ipynb"))
    nbformat.write(_instructor(title), str(root / "examples" / "solution.ipynb"))
    nbformat.write(_student(_IMPORTS, _WRONG), str(root / "examples" / "wrong-left-endpoints.ipynb"))
    (root / "examples" / "expected.toml").write_text(_EXPECTED.format(name=name), encoding="utf-8")
    return root
