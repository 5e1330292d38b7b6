"""Start-up cost of the command line: `--help` and `--version` import nothing heavy.

Checked through ``sys.modules`` in a fresh interpreter, never by timing (the
machine may be busy); ``benchmarks/engine_vs_peers.py`` prints the times.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import autograder

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
