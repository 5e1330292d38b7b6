"""The bare floor: student cells and the same pytest checks in one warm process, no isolation.

Usage (by ``engine_vs_peers.py`` and ``engine_profile.py``): ``python benchmarks/_floor.py
ASSIGNMENT [--public-only] [--warm K] NOTEBOOK...``. Imports and collection happen
once; then, for every notebook, its code cells run in a fresh namespace (IPython's
transformer turns magics into Python, no kernel) and every collected check item runs
against that namespace through pytest's own per-item protocol, with the ``student``,
``credit``, ``rng`` and ``feedback`` fixtures reduced to direct calls. Nothing crosses
a process, nothing is sandboxed, nothing is written: what is left is the student's code and
the checks' own work, the least any grader must spend. A check scores as in the engine: its
points, the part a ``credit.partial`` gives, or nothing; the ``variant`` fixture gives the
student's variant as the engine looks it up (the student's id is the folder above the
notebook's, ``<id>/<assignment>/<notebook>.ipynb``). Prints one JSON line:
the CPU and wall seconds of the per-notebook loop, each notebook's score, the best score, and each
notebook's CPU seconds in its cells and in its checks. With ``--warm K`` the first
``K`` notebooks run once before the loop and are not counted (the first import of a
library a notebook uses, which the engine's warm parent has already made).
"""

from __future__ import annotations

import itertools
import json
import os
import sys
import time
import types
import zlib
from pathlib import Path
from typing import Any

import autograder  # first: it keeps jsonschema's slow optional IRI grammar out (see there)
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import nbformat  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from _pytest.runner import runtestprotocol  # noqa: E402
from IPython.core.inputtransformer2 import TransformerManager  # noqa: E402

from autograder.engine.assignment import Assignment, load_assignment  # noqa: E402
from autograder.engine.plugin import Credit, VariantView, check_name, item_points  # noqa: E402
from autograder.errors import NoVariant, PartialCredit  # noqa: E402


class _Feedback:
    """The ``feedback`` fixture's calls, doing nothing (the floor writes nothing)."""

    def image(self, label: str, png: bytes) -> None:
        pass

    def input(self, text: str) -> None:
        pass


class FloorPlugin:
    """Collects the check items once; runs them for each notebook in ``pytest_runtestloop``."""

    def __init__(self, notebooks: list[Path], assignment: Assignment) -> None:
        self.notebooks, self.assignment = notebooks, assignment
        self.workdir = assignment.root
        self.namespace: dict[str, Any] = {}
        #: the id of the notebook being graded (the folder above its assignment's folder);
        #: not ``self.student``, which is the fixture of that name
        self.student_id = ""
        #: the part of its points the item that just ran earned (1, a partial credit, or 0)
        self.fraction = 0.0
        self.scores: list[float] = []
        #: the points of every collected check (a notebook's best score)
        self.max_score = 0.0
        self.cpu = self.wall = 0.0
        #: notebooks run first and not measured (``--warm K``)
        self.warm = 0
        #: per measured notebook: CPU seconds of its cells, and of its check items
        self.cells_cpu: list[float] = []
        self.checks_cpu: list[float] = []

    def pytest_configure(self, config: pytest.Config) -> None:
        config.addinivalue_line("markers", "points(n): points awarded by this check item")

    @pytest.fixture
    def student(self) -> types.SimpleNamespace:
        namespace = self.namespace

        def batch(name: str, items: Any, timeout: float | None = None) -> Any:
            return itertools.starmap(namespace[name], items)  # student.map, called directly

        return types.SimpleNamespace(**namespace, figures=lambda: [], map=batch)

    @pytest.fixture
    def credit(self) -> Credit:
        return Credit()

    @pytest.fixture
    def rng(self, request: pytest.FixtureRequest) -> np.random.Generator:
        name, _ = check_name(request.node)
        return np.random.default_rng([0, zlib.crc32(name.encode())])

    @pytest.fixture
    def feedback(self) -> _Feedback:
        return _Feedback()

    @pytest.fixture
    def variant(self) -> VariantView:
        spec = self.assignment.variants
        found = spec.lookup(self.assignment.name, self.student_id) if spec is not None else None
        if found is None:  # the engine's verdict: a person grades it, 0 points here
            raise NoVariant(f"{self.student_id!r} has no variant")
        return VariantView(found)

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_makereport(self, item: pytest.Item,
                                  call: pytest.CallInfo[None]) -> pytest.TestReport:
        # A bare report, as the engine's grading plugin makes one: the traceback of a
        # failing check is never formatted (it would cost the floor what no grader needs).
        failed = call.excinfo is not None
        if call.when == "call":
            value = call.excinfo.value if failed else None
            self.fraction = 1.0 if not failed else \
                value.fraction if isinstance(value, PartialCredit) else 0.0
        return pytest.TestReport(item.nodeid, item.location, {},
                                 "failed" if failed else "passed", "failed" if failed else None,
                                 call.when, duration=call.duration, start=call.start,
                                 stop=call.stop)

    def pytest_runtestloop(self, session: pytest.Session) -> bool:
        self.max_score = sum(item_points(item) for item in session.items)
        transform = TransformerManager().transform_cell
        sources = [(p.parent.parent.name, [transform(c.source) for c in
                                           nbformat.read(p, as_version=4).cells
                                           if c.cell_type == "code"]) for p in self.notebooks]
        os.chdir(self.workdir)
        for student, cells in sources[:self.warm]:  # unmeasured: first imports the cells need
            self._grade(student, cells, session)
        for kept in (self.scores, self.cells_cpu, self.checks_cpu):
            kept.clear()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        for student, cells in sources[self.warm:]:
            self._grade(student, cells, session)
        self.cpu, self.wall = time.process_time() - cpu0, time.perf_counter() - wall0
        return True

    def _grade(self, student: str, cells: list[str], session: pytest.Session) -> None:
        """Run one notebook's cells, then every item; its score and CPU split are kept."""
        start = time.process_time()
        self.namespace, self.student_id = {"__name__": "__main__"}, student
        for code in cells:
            try:
                exec(compile(code, "<cell>", "exec"), self.namespace)
            except Exception:
                pass  # a cell that raises is skipped, as the engine does
        plt.close("all")
        ran = time.process_time()
        score = 0.0
        for item in session.items:
            self.fraction = 0.0  # stays 0 when the setup fails (a missing variant, say)
            runtestprotocol(item, nextitem=None, log=False)
            score += item_points(item) * self.fraction
        self.scores.append(score)
        self.cells_cpu.append(ran - start)
        self.checks_cpu.append(time.process_time() - ran)


def main(argv: list[str]) -> int:
    public_only = "--public-only" in argv
    args = [a for a in argv if a != "--public-only"]
    warm = 0
    if "--warm" in args:  # --warm K: the first K notebooks run once, unmeasured
        at = args.index("--warm")
        warm = int(args[at + 1])
        del args[at:at + 2]
    assignment = load_assignment(Path(args[0]))
    checks = assignment.root / "checks"
    files = sorted((checks / "public").glob("test_*.py"))
    if not public_only:
        files += sorted((checks / "hidden").glob("test_*.py"))
    plugin = FloorPlugin([Path(a).resolve() for a in args[1:]], assignment)
    plugin.warm = warm
    sys.path.insert(0, str(checks / "public"))
    code = pytest.main([str(f) for f in files] + [
        "-c", os.devnull, "--rootdir", str(assignment.root), "--confcutdir", str(assignment.root),
        "-p", "no:cacheprovider", "-p", "no:terminal", "--assert=plain",
        "--import-mode=importlib"], plugins=[plugin])
    print(json.dumps({"cpu": plugin.cpu, "wall": plugin.wall, "scores": plugin.scores,
                      "max_score": plugin.max_score,
                      "cells_cpu": plugin.cells_cpu, "checks_cpu": plugin.checks_cpu,
                      "pytest_exit": int(code)}))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
