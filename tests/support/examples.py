"""A shipped assignment released and its examples graded in one batch, read by several tests."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tests.support import envs

#: student folders of each assignment's examples batch: each gives other unseen data
EXAMPLE_STUDENTS = tuple(f"student-{k}" for k in range(4))


@dataclass(frozen=True)
class ExamplesBatch:
    """An assignment released and its examples graded (:func:`release_and_grade`)."""

    work: Path
    #: the examples' stems (``examples/*.ipynb``)
    examples: tuple[str, ...]

    @property
    def release(self) -> Path:
        return self.work / "release"

    def results(self) -> list[dict[str, Any]]:
        """Every ``results.json`` of the examples' copies (the template's left out)."""
        found = [json.loads(path.read_text())
                 for path in sorted(self.work.glob("results/*/results.json"))]
        return [r for r in found if Path(r["extra_data"]["source"]).parent.name in EXAMPLE_STUDENTS]

    def copies(self, stem: str) -> list[dict[str, Any]]:
        """The results of example ``stem``, one per student folder."""
        return [r for r in self.results() if Path(r["extra_data"]["source"]).stem == stem]

    def template(self) -> dict[str, Any]:
        return json.loads((self.work / "results" / "template" / "results.json").read_text())


def release_and_grade(name: str, work: Path) -> ExamplesBatch:
    """Release ``name`` into ``work/release`` with the real CLI (``autograder release``), then
    grade in one batch (``autograder grade --jobs 2``) every example under each student folder
    of :data:`EXAMPLE_STUDENTS` (other students, other unseen data) and the released template."""
    cli = [sys.executable, "-m", "autograder"]
    released = subprocess.run([*cli, "release", name, "--out", str(work / "release")],
                              capture_output=True, text=True, timeout=600)
    assert released.returncode == 0, released.stderr
    examples = sorted((envs.ROOT / "assignments" / name / "examples").glob("*.ipynb"))
    for student in EXAMPLE_STUDENTS:
        (work / "in" / student).mkdir(parents=True)
        for path in examples:
            shutil.copy(path, work / "in" / student / path.name)
    shutil.copy(next((work / "release").glob("*.ipynb")), work / "in" / "template.ipynb")
    graded = subprocess.run([*cli, "grade", name, str(work / "in"), "--out", str(work / "results"),
                             "--jobs", "2", "--no-progress"], capture_output=True, text=True,
                            timeout=1800)
    assert graded.returncode == 0, graded.stderr[-3000:]
    return ExamplesBatch(work, tuple(p.stem for p in examples))
