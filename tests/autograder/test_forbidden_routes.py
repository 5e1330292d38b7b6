"""Forbidden means unusable from student code, whatever the route (issue 24, point 5).

Each route is a problem notebook: a shipped solution with one more cell that
redefines a graded function through the route. Every check of that function must
meet a ``forbidden`` verdict; routes the engine can only detect also put the
submission on the "needs a person" list. The honest solutions, which plot through
the very modules the students may not call, keep full marks.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

ROOT = Path(__file__).resolve().parents[2]

_FIND_CLASS = (
    "    def every(c, found):\n"
    "        for s in type.__subclasses__(c):\n"
    "            if s not in found:\n"
    "                found.append(s)\n"
    "                every(s, found)\n"
    "        return found\n"
    "    cls = next(c for c in every(object, []) if c.__name__ == {name!r})\n")

#: hull forbids scipy.spatial; matplotlib.path is for matplotlib's own use only
HULL_ROUTES = {
    "qhull-cython-class": _FIND_CLASS.format(name="_Qhull") + (
        "    q = cls(b'i', np.asarray(points, float), b'', required_options=None)\n"
        "    return [int(i) for i in q.get_extremes_2d()]\n"),
    "convexhull-by-subclasses": _FIND_CLASS.format(name="ConvexHull") + (
        "    return [int(i) for i in cls(np.asarray(points, float)).vertices]\n"),
    "subclass-of-found-class": _FIND_CLASS.format(name="ConvexHull") + (
        "    class Mine(cls):\n        pass\n"
        "    return [int(i) for i in Mine(np.asarray(points, float)).vertices]\n"),
    "path-alias-in-lines": (
        "    import matplotlib.lines as ml\n"
        "    pts = np.asarray(points, float)\n"
        "    inside = ml.Path(pts).contains_points(pts, radius=-1e-9)\n"
        "    return [i for i in range(len(pts)) if not inside[i]]\n"),
    "reload-qhull": (
        "    import importlib, sys\n"
        "    m = importlib.reload(sys.modules['scipy.spatial.' + '_qhull'])\n"
        "    return [int(i) for i in m.ConvexHull(np.asarray(points, float)).vertices]\n"),
}

#: bezier forbids matplotlib.bezier, which matplotlib itself draws with
BEZIER_ROUTES = {
    "alias-in-matplotlib-path": (
        "    import matplotlib.path as mp\n"
        "    return mp.BezierSegment(np.asarray(ctrlpts, float)).point_at_t(t)\n"),
    "segment-made-by-the-library": (
        "    import matplotlib.path as mp\n"
        "    pts = np.asarray(ctrlpts, float)\n"
        "    codes = [1] + [4] * (len(pts) - 1) if len(pts) == 4 else None\n"
        "    seg = next(iter(mp.Path(pts, codes).iter_bezier()))[0] if codes else \\\n"
        "        mp.BezierSegment(pts)\n"
        "    return seg.point_at_t(t)\n"),
    "class-by-subclasses": _FIND_CLASS.format(name="BezierSegment") + (
        "    return cls(np.asarray(ctrlpts, float)).point_at_t(t)\n"),
    "sys-modules-computed": (
        "    import sys\n"
        "    m = sys.modules['matplotlib.' + 'bez' + 'ier']\n"
        "    left, right = m.split_de_casteljau(np.asarray(ctrlpts, float), t)\n"
        "    return np.asarray(left)[-1]\n"),
    "dunder-import-computed": (
        "    m = __import__('matplotlib.' + 'bezier', fromlist=['x'])\n"
        "    return m.BezierSegment(np.asarray(ctrlpts, float)).point_at_t(t)\n"),
    "reload-fresh-copy": (
        "    import importlib, sys\n"
        "    m = importlib.reload(sys.modules['matplotlib.' + 'bezier'])\n"
        "    return m.BezierSegment(np.asarray(ctrlpts, float)).point_at_t(t)\n"),
    "vectorize-trampoline": (
        "    import matplotlib.path as mp\n"
        "    line = mp.Path(np.array([[0.0, 0.0], [1.0, 1.0]]), [1, 2])\n"
        "    seg = next(iter(line.iter_bezier()))[0]  # made by the library\n"
        "    return np.vectorize(seg.point_at_t, signature='()->(n)')(t)\n"),
    "source-copied": (
        "    import matplotlib.path as mp, os\n"
        "    ns = {}\n"
        "    folder = os.path.dirname(mp.__file__)\n"
        "    exec(open(os.path.join(folder, 'bez' + 'ier.py')).read(), ns)\n"
        "    return ns['BezierSegment'](np.asarray(ctrlpts, float)).point_at_t(t)\n"),
    "subclass-of-alias": (
        "    import matplotlib.path as mp\n"
        "    class Mine(mp.BezierSegment):\n        pass\n"
        "    return Mine(np.asarray(ctrlpts, float)).point_at_t(t)\n"),
    "tracer-for-frames": (
        "    import sys\n"
        "    sys.settrace(lambda frame, event, arg: None)\n"
        "    return np.asarray(ctrlpts, float)[0]\n"),
}

HEADERS = {"hull": "import numpy as np\ndef convex_hull(points):\n",
           "bezier": "import numpy as np\ndef de_casteljau(ctrlpts, t):\n"}
ROUTES = {"hull": HULL_ROUTES, "bezier": BEZIER_ROUTES}
GRADED = {"hull": "convex_hull", "bezier": "de_casteljau"}
#: routes that go through links rather than names: the scan asks a person as well
DETECTED = {"qhull-cython-class", "convexhull-by-subclasses", "subclass-of-found-class",
            "class-by-subclasses", "tracer-for-frames"}


def _write(name: str, route: str, body: str, folder: Path) -> None:
    book = nbformat.read(ROOT / "assignments" / name / "examples" / "solution.ipynb",
                         as_version=4)
    book.cells.append(nbformat.v4.new_code_cell(HEADERS[name] + body))
    nbformat.write(book, folder / f"{route}.ipynb")


@pytest.fixture(scope="module", params=sorted(ROUTES))
def graded(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
           ) -> tuple[str, dict[str, dict]]:
    name = request.param
    work = tmp_path_factory.mktemp(name)
    folder = work / "in"
    folder.mkdir()
    for route, body in ROUTES[name].items():
        _write(name, route, body, folder)
    book = ROOT / "assignments" / name / "examples" / "solution.ipynb"
    (folder / "honest.ipynb").write_bytes(book.read_bytes())
    out = work / "out"
    proc = subprocess.run([sys.executable, "-m", "autograder", "grade", name, str(folder),
                           "--out", str(out), "--public-only", "--no-progress"],
                          capture_output=True, text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return name, {p.parent.name: json.loads(p.read_text()) for p in out.glob("*/results.json")}


def _kind(test: dict) -> str:
    return str(test["extra_data"]["kind"])


@pytest.mark.slow
def test_every_route_meets_a_forbidden_verdict(graded: tuple[str, dict[str, dict]]) -> None:
    name, results = graded
    assert set(ROUTES[name]) | {"honest"} <= set(results)
    for route in ROUTES[name]:
        checks = [t for t in results[route]["tests"] if t["name"].startswith(GRADED[name])]
        kinds = {(t["name"], _kind(t), t["score"], t["output"][:200]) for t in checks}
        assert checks and all(_kind(t) == "forbidden" and t["score"] == 0 for t in checks), \
            (route, kinds)
        assert any("not allowed" in t["output"] for t in checks), route


@pytest.mark.slow
def test_routes_through_links_go_to_a_person(graded: tuple[str, dict[str, dict]]) -> None:
    name, results = graded
    for route in DETECTED & set(ROUTES[name]):
        notes = " ".join(results[route]["extra_data"]["notes"])
        assert "For the instructor: " in notes and GRADED[name] in notes, route


@pytest.mark.slow
def test_the_honest_solution_still_plots_and_scores_full_marks(
        graded: tuple[str, dict[str, dict]]) -> None:
    _, results = graded
    honest = results["honest"]
    assert honest["tests"] and all(_kind(t) == "ok" for t in honest["tests"]), \
        [(t["name"], _kind(t), t["output"][:300]) for t in honest["tests"] if _kind(t) != "ok"]
    assert not any(e["ename"] for e in honest.get("cell_errors", [])), honest.get("cell_errors")


# -- the mechanism, on a library made for the test -------------------------------------

_LIBRARY = {
    "fakelib/__init__.py": "",
    "fakelib/secret.py": "def answer(x, callback=None):\n"
                         "    if callback is not None:\n        callback()\n"
                         "    return 42 + x\n",
    "fakelib/user.py": "from fakelib.secret import answer\n\n"
                       "def use(callback=None):\n    return answer(1, callback)\n",
}

_SCRIPT = """
import sys
import fakelib.secret, fakelib.user
original = fakelib.secret.answer
from autograder.worker import gate, guard
guard.forbid(["fakelib.secret"], internal_use=["fakelib.secret"], reason="Do it yourself.")
results = {}
def cell(name, source):
    namespace = {"fakelib": fakelib, "sys": sys}
    try:
        exec(compile(source, "<ipython-input-1-0>", "exec"), namespace)
        results[name] = repr(namespace.get("out"))
    except gate.NotAllowedError as exc:
        results[name] = "refused: " + str(exc)
cell("library", "out = fakelib.user.use()")
cell("direct", "out = fakelib.secret.answer(1)")
cell("alias", "out = fakelib.user.answer(1)")
cell("frames-in-callback", "out = fakelib.user.use(lambda: sys._getframe(0).f_back)")
cell("ctypes", "import ctypes\\nout = ctypes.string_at(id(1), 8)")
entry = fakelib.user.answer
reachable = [c.cell_contents for c in entry.__closure__ or ()] + list(vars(gate).values())
results["original-reachable"] = repr(any(v is original for v in reachable))
print(repr(results))
"""


def test_internal_names_answer_only_the_library_that_needs_them(tmp_path: Path) -> None:
    for relative, text in _LIBRARY.items():
        (tmp_path / relative).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / relative).write_text(text)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    proc = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True,
                          env=env, timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    results = ast.literal_eval(proc.stdout.strip().splitlines()[-1])
    assert results["library"] == "43"
    for route in ("direct", "alias"):
        assert results[route].startswith("refused: `fakelib.secret.answer` is not allowed"), route
        assert "Do it yourself." in results[route]
    assert results["frames-in-callback"].startswith("refused: Taking frames")
    assert results["ctypes"].startswith("refused: `ctypes.")
    assert results["original-reachable"] == "False"
