"""The benchmarks' results files and the page made from them (no benchmark is run here).

``benchmarks/_record.py`` writes one JSON file per run; ``benchmarks/report.py`` turns
a folder of them into ``docs/performance.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCHMARKS / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def record_module() -> ModuleType:
    return _load("_record")


@pytest.fixture(scope="module")
def report_module() -> ModuleType:
    return _load("report")


MACHINE = {"cpu": "AMD EPYC", "cores": 2, "memory_gib": 7.8, "kernel": "Linux 6.1.0",
           "python": "3.11.7", "numpy": "1.26.4", "scipy": "1.11.4"}


def sample(name: str, figures: list[dict[str, Any]], load: float) -> dict[str, Any]:
    return {"schema": 1, "name": name, "date": "2026-12-04T10:00:00+00:00", "seconds": 12.5,
            "command": f"python benchmarks/{name}.py --count 10",
            "commit": {"sha": "0123456789abcdef0123456789abcdef01234567", "dirty": False},
            "machine": {**MACHINE, "load_average_start": [load, 1.0, 0.5],
                        "load_average_end": [load + 0.5, 1.1, 0.6]},
            "notes": f"notes of {name}", "figures": figures}


@pytest.fixture
def folders(tmp_path: Path) -> tuple[Path, Path]:
    """A results folder with two runs, and a scripts folder with one script not yet run."""
    results, scripts = tmp_path / "results", tmp_path / "scripts"
    results.mkdir()
    scripts.mkdir()
    main = '\n\nif __name__ == "__main__":\n    main()\n'
    (scripts / "zeta_vs_scipy.py").write_text('"""Zeta against SciPy."""' + main)
    (scripts / "alpha_costs.py").write_text('"""What alpha costs."""' + main)
    (scripts / "never_run.py").write_text('"""Not run yet."""' + main)
    (scripts / "_helper.py").write_text('"""A helper."""' + main)
    (scripts / "cases.py").write_text('"""Cases only, no main."""\n')
    (results / "zeta_vs_scipy.json").write_text(json.dumps(sample("zeta_vs_scipy", [
        {"label": "hull, 1e5 points", "value": 0.003, "unit": "s", "peer": "SciPy",
         "peer_value": 0.014, "ratio": 0.214286},
        {"label": "memory peak", "value": 1621.4, "unit": "MiB"},
    ], 0.4)))
    (results / "alpha_costs.json").write_text(json.dumps(sample("alpha_costs", [
        {"label": "bare fork: CPU", "value": 2.55, "unit": "ms"},
        {"label": "same grades.csv", "value": True, "unit": ""},
    ], 3.2)))
    return results, scripts


@pytest.fixture
def page(report_module: ModuleType, folders: tuple[Path, Path]) -> str:
    """The page made from the two sample runs."""
    results, scripts = folders
    return str(report_module.render(report_module.load(results), scripts))


def test_the_page_has_one_table_per_benchmark_sorted(page: str) -> None:
    assert page.startswith("# Performance\n")
    assert page.index("## alpha_costs") < page.index("## zeta_vs_scipy")
    assert "What alpha costs." in page and "Zeta against SciPy." in page
    assert "- command: `python benchmarks/zeta_vs_scipy.py --count 10`" in page
    assert "- commit: `0123456789`; 2026-12-04 10:00:00 UTC, 12.5 s" in page
    assert "notes of zeta_vs_scipy" in page


def test_a_compared_table_has_peer_and_ratio_columns(page: str) -> None:
    zeta = page[page.index("## zeta_vs_scipy"):]
    assert "| figure | value | unit | peer | peer value | ratio |" in zeta
    assert "| hull, 1e5 points | 0.003 | s | SciPy | 0.014 | 0.21x |" in zeta
    assert "| memory peak | 1,621 | MiB |  |  |  |" in zeta
    alpha = page[page.index("## alpha_costs"):page.index("## zeta_vs_scipy")]
    assert "| figure | value | unit |\n| --- | ---: | --- |\n" in alpha
    assert "ratio" not in alpha.split("| figure |")[1]
    assert "| same grades.csv | yes |  |" in alpha


def test_every_table_says_where_and_how_busy(page: str) -> None:
    machine = ("- machine: AMD EPYC, 2 cores, 7.8 GiB, Linux 6.1.0, Python 3.11.7, "
               "numpy 1.26.4, scipy 1.11.4")
    assert page.count(machine + "\n") == 2
    assert "- load average: 3.20 at the start, 3.70 at the end" in page
    # the intro names the load the runs saw, and the busy run
    intro = " ".join(page[:page.index("## History")].split())
    assert "load averages of 0.40 to 3.70 on 2 cores" in intro
    assert "are noisier: here `alpha_costs`." in intro


def test_scripts_without_results_are_listed_as_not_measured(page: str) -> None:
    missing = page[page.index("## Not measured yet"):]
    assert "- not measured yet: run `python benchmarks/never_run.py`" in missing
    assert "_helper" not in missing and "cases" not in missing
    assert "alpha_costs" not in missing


def test_regenerating_without_new_results_changes_nothing(report_module: ModuleType,
                                                          folders: tuple[Path, Path],
                                                          tmp_path: Path) -> None:
    out = tmp_path / "performance.md"
    argv = ["--results", str(folders[0]), "--out", str(out)]
    assert report_module.main(argv) == 0
    first = out.read_text()
    assert report_module.main(argv) == 0
    assert out.read_text() == first


def test_record_writes_the_machine_the_commit_and_the_figures(record_module: ModuleType,
                                                             report_module: ModuleType,
                                                             tmp_path: Path) -> None:
    Figure = record_module.Figure
    path = tmp_path / "results" / "fork_floor.json"
    written = record_module.record("fork_floor", [
        Figure("warm parent: CPU", 9.2, "ms", "bare interpreter", 2.3),
        Figure("huge pages: collapsed", 57.0, "MiB"),
        Figure("first result", float("nan"), "s"),
    ], notes="10 forks per line", path=path)
    assert written == path
    run = json.loads(path.read_text())
    assert {"schema", "name", "date", "seconds", "command", "commit", "machine", "notes",
            "figures"} <= set(run)
    assert run["name"] == "fork_floor" and run["notes"] == "10 forks per line"
    assert run["date"].endswith("+00:00")
    assert set(run["commit"]) == {"sha", "dirty"}
    assert {"cpu", "cores", "memory_gib", "kernel", "python", "numpy", "scipy",
            "load_average_start", "load_average_end"} <= set(run["machine"])
    assert len(run["machine"]["load_average_start"]) == 3
    assert run["command"].startswith("python ")
    compared, plain, missing = run["figures"]
    assert compared == {"label": "warm parent: CPU", "value": 9.2, "unit": "ms",
                        "peer": "bare interpreter", "peer_value": 2.3, "ratio": 4.0}
    assert plain == {"label": "huge pages: collapsed", "value": 57.0, "unit": "MiB"}
    assert missing["value"] is None  # JSON has no NaN
    page = report_module.render(report_module.load(path.parent), tmp_path)
    assert "| warm parent: CPU | 9.20 | ms | bare interpreter | 2.30 | 4.00x |" in page
    assert "| first result | - | s |  |  |  |" in page


def test_the_json_option_defaults_to_the_results_folder(record_module: ModuleType) -> None:
    parser = argparse.ArgumentParser()
    record_module.add_json_option(parser, "scale")
    assert parser.parse_args([]).json == record_module.RESULTS / "scale.json"
    assert parser.parse_args(["--json", "x.json"]).json == Path("x.json")
