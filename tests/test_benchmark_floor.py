"""The bare floor (``benchmarks/_floor.py``) scores the hull examples as the engine must.

The floor is the peer the engine's overhead is measured against, and it is fair only
while it does the checks' work as the engine does. A check it cannot run (a fixture it
lacks, a method its stand-ins miss) fails at once, costs it nothing and loses its points,
so its scores show it: every shipped hull example, laid out as the benchmarks grade it,
lands in the band ``examples/expected.toml`` sets for the engine. The exception is
``uses-scipy``, which the engine refuses: the floor has no forbidden list, so it scores
the hull checks too.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
HULL = ROOT / "assignments" / "hull"


def test_the_floor_scores_each_hull_example_in_the_engines_band(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(BENCHMARKS))  # the benchmarks import their helpers so
    import grade_vs_nbgrader  # the batch engine_vs_peers grades: <id>/hull/hull.ipynb

    examples = sorted(path.stem for path in (HULL / "examples").glob("*.ipynb"))
    notebooks = grade_vs_nbgrader.build_batch(tmp_path / "submitted", len(examples))
    run = subprocess.run([sys.executable, str(BENCHMARKS / "_floor.py"), str(HULL),
                          *map(str, notebooks)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["pytest_exit"] == 0 and report["max_score"] > 0
    bands = tomllib.loads((HULL / "examples" / "expected.toml").read_text(encoding="utf-8"))
    fractions = {name: score / report["max_score"]
                 for name, score in zip(examples, report["scores"], strict=True)}
    assert fractions["uses-scipy"] > bands["uses-scipy"]["max"], fractions
    for name, fraction in fractions.items():
        if name != "uses-scipy":
            band = bands[name]
            assert band["min"] <= fraction <= band["max"], (name, fraction, band)
