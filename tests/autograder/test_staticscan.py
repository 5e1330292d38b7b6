"""Static scan for forbidden names: aliases, star imports, taint, dynamic code, magics."""

from __future__ import annotations

import ast
import subprocess
import sys

import pytest

from autograder.engine.scanfindings import ScanFindings, Use
from autograder.engine.staticscan import scan
from autograder.errors import UsageError

SPATIAL = ["scipy.spatial"]
SPLINE = ["scipy.interpolate.CubicSpline"]


def where(report: ScanFindings) -> list[tuple[str | None, int, int]]:
    """``(function, cell, line)`` of each use."""
    return [(u.function, u.cell, u.line) for u in report.uses]


# -- aliases -------------------------------------------------------------------------

@pytest.mark.parametrize("setup, call", [
    ("import scipy.spatial as sp", "sp.ConvexHull(p)"),
    ("from scipy.spatial import ConvexHull as CH", "CH(p)"),
    ("from scipy import spatial", "spatial.ConvexHull(p)"),
    ("import scipy", "scipy.spatial.Delaunay(p)"),
    ("import scipy.spatial", "scipy.spatial.Delaunay(p)"),
    ("from scipy.spatial import *", "ConvexHull(p)"),
    ("from scipy import *", "spatial.ConvexHull(p)"),
    ("import scipy.spatial as sp\nH = sp.ConvexHull", "H(p)"),
    ("import scipy", "getattr(scipy, 'spatial').ConvexHull(p)"),
    ("import importlib", "importlib.import_module('scipy.spatial').ConvexHull(p)"),
    ("from importlib import import_module as im", "im('scipy.spatial').ConvexHull(p)"),
    ("import sys", "sys.modules['scipy.spatial'].ConvexHull(p)"),
    ("import scipy.spatial._qhull as q", "q.ConvexHull(p)"),
])
def test_aliases_resolve(setup: str, call: str) -> None:
    report = scan([setup, f"def hull(p):\n    return {call}\n"], SPATIAL)
    assert "hull" in report.tainted
    use = next(u for u in report.uses if u.function == "hull")
    assert (use.name, use.cell, use.line, use.text) == ("scipy.spatial", 1, 2, f"return {call}")


def test_unrelated_scipy_use_is_not_tainted() -> None:
    report = scan(["import scipy\nimport numpy as np\nfrom scipy import linalg",
                   "def f(p):\n    return scipy.linalg.norm(p) + np.sum(p) + linalg.det(p)"],
                  SPATIAL)
    assert report.uses == () and report.tainted == frozenset()


def test_attribute_rule_matches_only_that_attribute() -> None:
    report = scan(["import scipy.interpolate as si",
                   "def bad(x, y):\n    return si.CubicSpline(x, y)",
                   "def fine(x, y):\n    return si.PchipInterpolator(x, y)"], SPLINE)
    assert report.tainted == {"bad"}
    assert {u.name for u in report.uses} == {"scipy.interpolate.CubicSpline"}


def test_attribute_rule_matches_submodule_qualified_forms() -> None:
    report = scan(["import scipy.interpolate._cubic as c\nfrom scipy.interpolate import _cubic",
                   "def f(x, y):\n    return c.CubicSpline(x, y)",
                   "def g(x, y):\n    return _cubic.CubicSpline(x, y)",
                   "def h(x, y):\n    return c.PchipInterpolator(x, y)"], SPLINE)
    assert report.tainted == {"f", "g"}


def test_star_import_of_a_parent_module() -> None:
    report = scan(["from scipy.interpolate import *",
                   "def f(x, y):\n    return CubicSpline(x, y)",
                   "def g(x, y):\n    return interp1d(x, y)"], SPLINE)
    assert "f" in report.tainted and "g" not in report.tainted
    assert where(report) == [("f", 1, 2)]  # the star import alone is not a use


def test_star_import_of_a_forbidden_module_does_not_capture_builtins() -> None:
    report = scan(["from scipy.spatial import *",
                   "def f(p):\n    print(len(p))\n    return sorted(p)"], SPATIAL)
    assert "f" not in report.tainted and where(report) == [(None, 0, 1)]


# -- scopes ---------------------------------------------------------------------------

def test_module_level_import_is_a_use_but_taints_no_function() -> None:
    report = scan(["import scipy.spatial\nfrom scipy.spatial import ConvexHull",
                   "def f(p):\n    return p"], SPATIAL)
    assert where(report) == [(None, 0, 1), (None, 0, 2)]
    assert "f" not in report.tainted


def test_import_inside_a_function_taints_it() -> None:
    report = scan(["def f(p):\n    from scipy.spatial import ConvexHull\n    return 1"], SPATIAL)
    assert report.tainted == {"f"} and where(report) == [("f", 0, 2)]


def test_local_names_shadow_imports() -> None:
    report = scan(["from scipy.spatial import ConvexHull",
                   "def f(ConvexHull):\n    return ConvexHull(1)",
                   "def g(p):\n    ConvexHull = sorted\n    return ConvexHull(p)",
                   "def h(p):\n    return [ConvexHull for ConvexHull in p]"], SPATIAL)
    assert not {"f", "g", "h"} & report.tainted


def test_later_rebinding_hides_the_import() -> None:
    report = scan(["from scipy.spatial import ConvexHull",
                   "def ConvexHull(p):\n    return p",
                   "def f(p):\n    return ConvexHull(p)"], SPATIAL)
    assert report.tainted == frozenset()


def test_function_defined_before_the_import_is_still_tainted() -> None:
    report = scan(["def f(p):\n    return CH(p)",
                   "from scipy.spatial import ConvexHull as CH"], SPATIAL)
    assert "f" in report.tainted


def test_redefined_function_uses_its_last_definition() -> None:
    report = scan(["import scipy.spatial as sp",
                   "def f(p):\n    return sp.ConvexHull(p)",
                   "def f(p):\n    return p"], SPATIAL)
    assert "f" not in report.tainted
    assert ("f", 1, 2) in where(report)  # the old use is still reported


def test_name_bound_to_a_forbidden_function_is_tainted() -> None:
    report = scan(["from scipy.spatial import ConvexHull as convex_hull",
                   "import scipy.spatial as sp\nhull = sp.ConvexHull\nlam = lambda p: sp.Delaunay(p)"],
                  SPATIAL)
    assert {"convex_hull", "hull", "lam"} <= report.tainted


def test_class_methods_taint_the_class_and_its_users() -> None:
    report = scan(["import scipy.spatial as sp",
                   "class Hull:\n    def __init__(self, p):\n        self.h = sp.ConvexHull(p)",
                   "def f(p):\n    return Hull(p).h"], SPATIAL)
    assert {"Hull", "f"} <= report.tainted
    assert ("Hull", 1, 3) in where(report)


def test_nested_function_use_belongs_to_the_top_level_function() -> None:
    report = scan(["import scipy.spatial as sp",
                   "def outer(p):\n    def inner(q):\n        return sp.Delaunay(q)\n"
                   "    return inner(p)"], SPATIAL)
    assert "outer" in report.tainted and ("outer", 1, 3) in where(report)


# -- call graph ---------------------------------------------------------------------------

def test_taint_flows_through_the_call_graph() -> None:
    report = scan(["import scipy.spatial as sp",
                   "def helper(p):\n    return sp.ConvexHull(p).vertices",
                   "def middle(p):\n    return helper(p)",
                   "def top(p):\n    return list(map(middle, [p]))",
                   "def recursive(p):\n    return recursive(p[1:]) if p else helper(p)",
                   "def clean(p):\n    return sorted(p)",
                   "def also_clean(p):\n    return clean(p)"], SPATIAL)
    assert {"helper", "middle", "top", "recursive"} <= report.tainted
    assert not {"clean", "also_clean"} & report.tainted


def test_module_level_results_of_forbidden_calls_taint_their_readers() -> None:
    report = scan(["from scipy.spatial import Delaunay\nimport numpy as np",
                   "pts = np.zeros((3, 2))\ntri = Delaunay(pts)",
                   "def f():\n    return tri.simplices",
                   "def g():\n    return pts"], SPATIAL)
    assert {"tri", "f"} <= report.tainted and not {"pts", "g"} & report.tainted


def test_global_import_in_a_function() -> None:
    report = scan(["def setup():\n    global CH\n    from scipy.spatial import ConvexHull as CH",
                   "def f(p):\n    return CH(p)"], SPATIAL)
    assert {"setup", "f"} <= report.tainted


# -- dynamic code ----------------------------------------------------------------------------

def test_dynamic_imports_and_exec_are_flagged() -> None:
    report = scan(["import importlib\nname = 'scipy.' + 'spatial'",
                   "def a(p):\n    return importlib.import_module(name).ConvexHull(p)",
                   "def b(p):\n    exec('import scipy.spatial')",
                   "def c(p):\n    return eval('p')",
                   "def d(p):\n    return __import__(name)",
                   "def e(p):\n    import scipy\n    return getattr(scipy, name)",
                   "def f(p):\n    return compile('1', 'x', 'eval')",
                   "def g(p):\n    return a(p)",
                   "def h(p, attr):\n    return getattr(p, attr)"], SPATIAL)
    assert [(u.name, u.function) for u in report.dynamic] == [
        ("importlib.import_module", "a"), ("exec", "b"), ("eval", "c"), ("__import__", "d"),
        ("getattr", "e"), ("compile", "f")]
    assert report.unverified == {"a", "b", "c", "d", "e", "f", "g"}
    assert report.tainted == frozenset() and report.uses == ()


def test_literal_dynamic_import_is_verified() -> None:
    report = scan(["def f(p):\n    m = __import__('scipy.spatial')\n    return m"], SPATIAL)
    assert report.tainted == {"f"} and report.dynamic == ()


def test_aliased_exec_is_flagged() -> None:
    report = scan(["run = exec", "def f():\n    run('import scipy.spatial')"], SPATIAL)
    assert [(u.name, u.function, u.cell) for u in report.dynamic] == [("exec", "f", 1)]


def test_user_function_named_eval_is_not_dynamic() -> None:
    report = scan(["def eval(x):\n    return x", "def f():\n    return eval(3)"], SPATIAL)
    assert report.dynamic == ()


def test_unverifiable_ipython_features_are_flagged() -> None:
    report = scan(["%%writefile helper.py\nfrom scipy.spatial import ConvexHull\n",
                   "%run helper.py", "get_ipython().ex('import scipy.spatial')"], SPATIAL)
    assert [u.name for u in report.dynamic] == ["%%writefile", "%run", "get_ipython().ex"]


# -- IPython syntax ------------------------------------------------------------------------

def test_magics_are_tolerated() -> None:
    report = scan(["%matplotlib inline\nimport numpy as np",
                   "%time total = sum(range(10))\n!ls\nfiles = !ls",
                   "np.zeros?\ndisplay(np.ones(2))",
                   "def f(p):\n    %time q = sorted(p)\n    return q"], SPATIAL)
    assert report.errors == () and report.uses == () and report.dynamic == ()


def test_code_inside_time_magics_is_scanned() -> None:
    report = scan(["%%time\nfrom scipy.spatial import ConvexHull\n"
                   "def convex_hull(points):\n    return ConvexHull(points)",
                   "import scipy.spatial as sp\n%time h = sp.ConvexHull(p)",
                   "%timeit -n 10 -r 3 sp.Delaunay(p)"], SPATIAL)
    assert "convex_hull" in report.tainted and "h" in report.tainted
    assert where(report) == [(None, 0, 2), ("convex_hull", 0, 4), (None, 1, 1), (None, 1, 2),
                             (None, 2, 1)]
    assert report.uses[1].text == "return ConvexHull(points)"
    assert report.errors == ()


# -- errors and edge cases ------------------------------------------------------------------

def test_syntax_error_is_recorded_and_other_cells_scanned() -> None:
    report = scan(["def f(:\n    pass", "x = (", "import scipy.spatial as sp",
                   "def g(p):\n    return sp.ConvexHull(p)"], SPATIAL)
    assert report.errors[0].startswith("cell 0, line 1: ")
    assert report.errors[1].startswith("cell 1, ")
    assert len(report.errors) == 2 and "g" in report.tainted


def test_very_deep_code_is_unverified_not_a_crash() -> None:
    """Where Python's parser gives up differs between 3.11 releases: a cell it cannot
    parse cannot run either; one it parses but the scan cannot walk is unverified."""
    cells = ["x = " + "+".join(["1"] * 3000), "y = f" + "()" * 3000]
    report = scan(cells, SPATIAL)
    assert report.errors and all("too deeply nested" in e for e in report.errors), report.errors
    flagged = {int(e.split(",")[0].removeprefix("cell ")) for e in report.errors}
    assert 1 in flagged, "a call chain 3000 deep is too deep for the scan in every version"
    assert all(u.name == "<too deeply nested>" for u in report.dynamic)
    # parsed but not walked: unverified; not even parsed: it cannot run either
    assert {u.cell for u in report.dynamic} == {c for c in flagged if _parses(cells[c])}


def _parses(source: str) -> bool:
    try:
        ast.parse(source)
    except RecursionError:
        return False
    return True


def test_empty_inputs() -> None:
    assert scan([], SPATIAL) == ScanFindings()
    assert scan(["import scipy.spatial"], []) == ScanFindings()


def test_uses_are_sorted_and_deduplicated() -> None:
    report = scan(["import scipy.spatial as sp",
                   "def f(p):\n    return sp.ConvexHull(p), sp.Delaunay(p)"], SPATIAL)
    assert report.uses == (
        Use("scipy.spatial", None, 0, 1, "import scipy.spatial as sp"),
        Use("scipy.spatial", "f", 1, 2, "return sp.ConvexHull(p), sp.Delaunay(p)"))


def test_report_is_frozen() -> None:
    report = scan(["x = 1"], SPATIAL)
    with pytest.raises(AttributeError):
        report.tainted = frozenset({"x"})  # type: ignore[misc]


@pytest.mark.parametrize("forbid", ["scipy.spatial", ["scipy spatial"], [3], ["scipy."]])
def test_bad_forbid_entries_are_usage_errors(forbid: object) -> None:
    with pytest.raises(UsageError):
        scan(["x = 1"], forbid)  # type: ignore[arg-type]


# -- the parse of plain Python skips IPython's token passes, with the same tree --------

#: cells in IPython syntax, and Python that looks like it
CELLS = [
    "import scipy.spatial as sp\nH = sp.ConvexHull",
    "\n\n  x = 1\n  y = x % 2",            # blank first lines and common indentation
    "In [1]: x = 1\n   ...: y = x",        # a pasted IPython prompt, which also parses as Python
    ">>> x = 1\n... y = 2",
    "x = (1\n% 2)\ny = 1 \\\n    % 2",     # a % at the start of a line inside an expression
    "a = 'text?'  # comment?\nb = f'{a!r}'",
    "%time x = 1", "!ls -l", "x = %pwd", "y = !echo hi", "len?", "/print 1 2", ",f a b",
    "%%timeit -n 2\nx = 1", "def f():\n    %time g()\n    return 1",
    "x = 1\n\tif x:\n  y",                  # not Python at all: the error comes from the full pass
]


@pytest.mark.parametrize("source", CELLS)
def test_plain_python_gets_the_tree_the_full_transform_gives(source: str) -> None:
    from IPython.core.inputtransformer2 import TransformerManager

    from autograder.engine.staticscan import _Analyzer, _Where

    analyzer = _Analyzer(tuple(SPATIAL))
    mine = analyzer._parse(source, _Where(cell=0, lines=tuple(source.splitlines())), "")
    try:
        theirs: ast.Module | None = ast.parse(TransformerManager().transform_cell(source))
    except SyntaxError:
        theirs = None
    assert (ast.dump(mine) if mine else None) == (ast.dump(theirs) if theirs else None)
    assert (mine is None) == bool(analyzer.errors)


@pytest.mark.parametrize("source", [
    *CELLS, "\rx = 1\ny = 2", "x = 1\r\r  y = 2", "[nav] In [1]: x = 1", "x = [\n...]",
    "x = (1,\n   ...)", "\fx = 1", "if x:\n    y = 1\n%time z", "def f():\n    return 1"])
def test_a_cell_parsed_without_ipython_gets_ipythons_tree(source: str) -> None:
    """A cell that IPython's line passes cannot change is parsed without importing
    IPython, with the tree (line numbers included) of the full transform."""
    from IPython.core.inputtransformer2 import TransformerManager

    from autograder.engine.scanipython import _untransformed

    mine = _untransformed(source)
    if mine is not None:
        assert ast.dump(mine, include_attributes=True) == ast.dump(
            ast.parse(TransformerManager().transform_cell(source)), include_attributes=True)


def test_plain_python_is_scanned_without_importing_ipython() -> None:
    code = ("import sys\n"
            "from autograder.engine.staticscan import scan\n"
            "scan(['import scipy.spatial as sp\\nH = sp.ConvexHull', 'def f(p):\\n    return p'],"
            " ['scipy.spatial'])\n"
            "print('IPython' in sys.modules)\n"
            "report = scan(['%time import scipy.spatial'], ['scipy.spatial'])\n"
            "print('IPython' in sys.modules, bool(report.uses))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "True", "True"]


@pytest.mark.parametrize("source", [
    "x = 1\n  # c\ns = \"\"\"\n  a\"\"\"", "  # c\ns = \"\"\"\n  a\"\"\"",  # indentation in strings
    "print(1)\n>>> x", "x = 1\n... y", "await f()", "async with a:\n    pass",
    "", "\n\n", "x = 1;", "1/0", "a = [1,\n,2]",
    *CELLS])
def test_the_worker_runs_the_text_the_full_transform_gives(source: str) -> None:
    """The worker's transformer (plain Python skips the token passes) gives the text,
    or raises the error, of IPython's whole ``transform_cell``."""
    from IPython.core.inputtransformer2 import TransformerManager

    from autograder.worker.execute import PythonFirst

    def outcome(manager: TransformerManager) -> str:
        try:
            return manager.transform_cell(source)
        except Exception as exc:  # noqa: BLE001 - compared, not handled
            return f"{type(exc).__name__}: {exc}"

    assert outcome(PythonFirst()) == outcome(TransformerManager())


def test_top_level_await_and_magics_still_run_in_the_worker_shell() -> None:
    """The worker's shell skips IPython's check for top-level ``await`` only in cells
    without the words ``await`` and ``async``: such cells still run, as do magics."""
    from autograder.worker.execute import make_shell

    shell = make_shell()
    try:
        ran = [shell.run_cell(code, store_history=False).success for code in (
            "import asyncio\nawait asyncio.sleep(0)\nawaited = 1",
            "async def g():\n    return 2\nasync_result = await g()",
            "%time timed = 3\nechoed = !echo hi",
            "plain = 'no coroutine here'")]
        assert ran == [True, True, True, True]
        assert [shell.user_ns[k] for k in ("awaited", "async_result", "timed", "echoed",
                                           "plain")] == [1, 2, 3, ["hi"], "no coroutine here"]
    finally:
        shell.clear_instance()
