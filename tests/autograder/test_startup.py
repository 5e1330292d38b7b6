"""Start-up cost of the command line: `--help` and `--version` import nothing heavy.

Checked through ``sys.modules`` in a fresh interpreter, never by timing (the
machine may be busy); ``benchmarks/engine_vs_peers.py`` prints the times.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import autograder
from tests.support.assignments import CHECK, RIGHT, submission, write_double

HEAVY = ("nbformat", "jsonschema", "numpy", "IPython", "pytest", "rfc3987_syntax", "scipy",
         "matplotlib", "tqdm", "fastapi", "sqlalchemy", "distributed")

PROBE = """
import json, sys
from autograder.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
heavy = {heavy!r}
loaded = sorted(m for m in sys.modules if m.split(".")[0] in heavy and sys.modules[m] is not None)
print(json.dumps({{"code": code, "loaded": loaded}}), file=sys.stderr)
"""


def _probe(*argv: str) -> tuple[dict[str, object], str]:
    proc = subprocess.run([sys.executable, "-c", PROBE.format(heavy=HEAVY), *argv],
                          capture_output=True, text=True, timeout=300)
    report = json.loads(proc.stderr.strip().splitlines()[-1])
    return report, proc.stdout


@pytest.mark.parametrize("argv", [("--help",), ("--version",), ("grade", "--help"),
                                  ("check", "--help"), ("serve", "--help")])
def test_help_and_version_import_nothing_heavy(argv: tuple[str, ...]) -> None:
    report, stdout = _probe(*argv)
    assert report["code"] == 0, stdout
    assert report["loaded"] == [], (
        f"`autograder {' '.join(argv)}` imported {report['loaded']}: import them inside the "
        "command that needs them (autograder/cli.py)")
    assert stdout.strip(), "nothing was printed"


def test_version_prints_the_package_version() -> None:
    proc = subprocess.run([sys.executable, "-m", "autograder", "--version"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"autograder {autograder.__version__}"


def test_nbformat_under_numgrade_skips_the_iri_grammar_and_still_validates() -> None:
    """jsonschema's optional IRI grammar is not imported; a schema error is still found."""
    code = """
import json, sys, autograder, nbformat
bad = {"nbformat": 4, "nbformat_minor": 5, "metadata": {},
       "cells": [{"cell_type": "code", "metadata": {}, "source": 3, "outputs": [],
                  "execution_count": None, "id": "a"}]}
try:
    nbformat.validate(bad)
    found = None
except nbformat.ValidationError as exc:
    found = exc.message
print(json.dumps({"grammar": "rfc3987_syntax" in sys.modules and sys.modules["rfc3987_syntax"]
                  is not None, "error": found}))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["grammar"] is False
    assert report["error"] and "3" in report["error"], report


EARLY = """
import json, sys
from autograder.engine import slot
from autograder.cli import main
engine = ("pytest", "nbformat", "autograder.engine.grader", "autograder.engine.checkrun", "reference",
          "numpy", "pyseccomp", "autograder.boundary.codec", "autograder.sandbox.reaper")
launches = []
launch = slot.GradingSlot._launch
def recording(self):
    launches.append(sorted(m for m in engine if m in sys.modules))
    launch(self)
slot.GradingSlot._launch = recording
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "launches": launches}), file=sys.stderr)
"""


def test_grade_check_and_validate_start_the_warm_parent_before_importing_the_engine(
        tmp_path: Path) -> None:
    """The warm parent's imports run beside the grader's (``slot.start_early``): it is
    launched before the engine, numpy (the frame codec's) and the sandbox's libraries are
    imported. A run that grades nothing, or fails, leaves neither its slot folder nor
    its process."""
    folder = write_double(tmp_path, "double", {"test_double.py": CHECK})
    notebook = submission(tmp_path / "submitted", "alice", RIGHT)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}

    def run(*argv: str) -> dict[str, object]:
        proc = subprocess.run([sys.executable, "-c", EARLY, *argv], capture_output=True,
                              text=True, timeout=600, env=env)
        report: dict[str, object] = json.loads(proc.stderr.strip().splitlines()[-1])
        report["stdout"] = proc.stdout
        return report

    out = tmp_path / "results"
    graded = run("grade", str(folder), str(notebook), "--out", str(out), "--no-progress")
    assert graded["code"] == 0 and graded["launches"] == [[]], graded
    assert json.loads((out / "alice" / "results.json").read_text())["score"] == 1.0
    reused = run("grade", str(folder), str(notebook), "--out", str(out), "--no-progress")
    assert reused["code"] == 0 and reused["launches"] == [[]], reused
    assert "reused 1 unchanged" in str(reused["stdout"])
    checked = run("check", str(notebook), "--assignment", str(folder))
    assert checked["code"] == 0 and checked["launches"] == [[]], checked
    missing = run("check", str(tmp_path / "nowhere.ipynb"), "--assignment", str(folder))
    assert missing["code"] != 0 and missing["launches"] == [[]], missing
    validated = run("validate", str(folder))
    assert validated["launches"] == [[]], validated
    assert "template" in str(validated["stdout"]), validated
    assert not list(scratch.glob("autograder-slot-*")), "a slot folder was left behind"


EXIT_PROBE = """
import atexit, gc, sys
atexit.register(lambda: print(f"frozen={{gc.get_freeze_count()}}", file=sys.stderr))
from autograder.cli import {entry}
sys.argv = ["autograder", "grade", "no-such-assignment", "nothing", "--out", "out"]
{call}
"""


@pytest.mark.parametrize("entry, call, frozen", [
    ("run", "run()", True),  # the command: its objects leave the collector's reach at exit
    ("main", "code = main()", False),  # a caller's own process is left as it was
])
def test_the_command_exits_without_walking_its_objects_and_keeps_the_status(
        tmp_path: Path, entry: str, call: str, frozen: bool) -> None:
    proc = subprocess.run([sys.executable, "-c", EXIT_PROBE.format(entry=entry, call=call)],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert ("frozen=0" not in proc.stderr) is frozen, proc.stderr[-2000:]
    assert "no-such-assignment" in proc.stderr
    if frozen:
        assert proc.returncode == 2  # main's status for a usage error, through run()


def test_the_installed_command_is_run() -> None:
    from importlib.metadata import entry_points

    command = [e for e in entry_points(group="console_scripts") if e.name == "autograder"]
    assert [e.value for e in command] == ["autograder.cli:run"]


def test_the_warm_parents_children_collect_as_a_fresh_interpreter_does(tmp_path: Path) -> None:
    """The warm parent starts with a higher threshold for the cyclic collector (fewer
    collections during its imports); a submission's child runs with the default."""
    from autograder.engine.assignment import load_assignment
    from autograder.engine.grader import Grader

    # In a fresh interpreter: importing the warm parent's module here would load its
    # libraries into the test process (and set matplotlib's backend for it).
    probe = ("import gc, json; fresh = list(gc.get_threshold())\n"
             "from autograder.worker.__main__ import STARTUP_GC_THRESHOLDS\n"
             "print(json.dumps([fresh, list(STARTUP_GC_THRESHOLDS)]))")
    fresh, startup = json.loads(subprocess.run([sys.executable, "-c", probe], capture_output=True,
                                               text=True, check=True, timeout=300).stdout)
    assert fresh != startup
    check = ("def test_double(student):\n"
             f"    assert student.thresholds() == {fresh!r}\n")
    folder = write_double(tmp_path, "double", {"test_double.py": check})
    code = RIGHT + "import gc\n\ndef thresholds():\n    return list(gc.get_threshold())\n"
    notebook = submission(tmp_path / "in", "s", code)
    with Grader(load_assignment(folder)) as grader:
        result = grader.grade(notebook)
    assert result.score == 1.0, [t.output for t in result.tests]
