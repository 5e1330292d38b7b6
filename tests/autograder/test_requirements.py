"""What an assignment needs: ``[assignment] requirements``, checked before the first submission.

Each requirement must be installed at an allowed version and import in a sandboxed
worker; otherwise grading stops with the package and the pip command, exit status
non-zero, and no result written.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.requirements import check_installed
from autograder.errors import AssignmentError
from tests.support.assignments import CHECK, RIGHT, submission, write_double

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow


def _assignment(root: Path, requirements: list[str]) -> Path:
    folder = write_double(root, "needs", {"test_double.py": CHECK})
    toml = folder / "assignment.toml"
    toml.write_text(toml.read_text() + f"requirements = {json.dumps(requirements)}\n")
    return folder


def _grade(root: Path, folder: Path, code: str, *, pythonpath: str = "") -> subprocess.CompletedProcess[str]:
    submission(root / "subs", "alice", code)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in (str(REPO), pythonpath) if p))
    return subprocess.run([sys.executable, "-m", "autograder", "grade", str(folder),
                           str(root / "subs"), "--out", str(root / "out")],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=600)


def _nothing_written(out: Path) -> bool:
    return not any(out.rglob("results.json")) and not (out / "grades.csv").exists()


def test_an_installed_package_imports_under_landlock(tmp_path: Path) -> None:
    """pandas lives in site-packages: the sandboxed worker reads and imports it."""
    folder = _assignment(tmp_path, ["pandas>=2"])
    ran = _grade(tmp_path, folder, "import pandas as pd\n" + RIGHT
                 + "frame = pd.DataFrame({'a': [1, 2]})\nprint('rows', len(frame))")
    assert ran.returncode == 0, ran.stderr
    result = json.loads((tmp_path / "out" / "alice" / "results.json").read_text())
    assert result["score"] == pytest.approx(result["max_score"])
    assert "rows 2" in result["extra_data"]["stdout"]


def test_a_missing_package_stops_grading_before_any_result(tmp_path: Path) -> None:
    folder = _assignment(tmp_path, ["pandas>=2", "numgrade-no-such-package>=1"])
    ran = _grade(tmp_path, folder, RIGHT)
    assert ran.returncode != 0
    assert "needs 'numgrade-no-such-package>=1'" in ran.stderr
    assert "-m pip install 'numgrade-no-such-package>=1'" in ran.stderr
    assert "Traceback" not in ran.stderr
    assert _nothing_written(tmp_path / "out")


def test_a_version_too_old_names_the_installed_one(tmp_path: Path) -> None:
    with pytest.raises(AssignmentError, match=r"needs 'numpy>=999', and numpy \S+ is installed; "
                                               r"install a version it allows with: .* -m pip "
                                               r"install 'numpy>=999'"):
        check_installed(["numpy>=999"], where="The assignment 'x'")


def test_a_requirement_that_does_not_parse_is_named(tmp_path: Path) -> None:
    folder = _assignment(tmp_path, ["pandas >= = 2"])
    ran = _grade(tmp_path, folder, RIGHT)
    assert ran.returncode != 0
    assert "requirement 'pandas >= = 2' cannot be read" in ran.stderr
    assert _nothing_written(tmp_path / "out")


def _fake_distribution(site: Path) -> None:
    """``numgrade-outside`` 1.0, installed where the interpreter does not keep packages."""
    (site / "numgrade_outside").mkdir(parents=True)
    (site / "numgrade_outside" / "__init__.py").write_text("VALUE = 1\n")
    info = site / "numgrade_outside-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: numgrade-outside\nVersion: 1.0\n")
    (info / "top_level.txt").write_text("numgrade_outside\n")


def test_a_package_the_sandbox_cannot_read_stops_grading(tmp_path: Path) -> None:
    """Installed for the grader (on PYTHONPATH), unreadable for the worker: said before grading.

    Without the worker's import check, every submission's ``import numgrade_outside``
    would fail, and the class would get zeros for the grader's install.
    """
    site = tmp_path / "site"
    _fake_distribution(site)
    folder = _assignment(tmp_path, ["numgrade-outside>=1"])
    ran = _grade(tmp_path, folder, "import numgrade_outside\n" + RIGHT, pythonpath=str(site))
    assert ran.returncode != 0, ran.stdout
    assert "needs 'numgrade-outside>=1', and `import numgrade_outside` fails in the sandboxed " \
           "worker" in ran.stderr
    assert "ModuleNotFoundError" in ran.stderr
    assert _nothing_written(tmp_path / "out")


def test_requirements_key_must_be_a_list_of_strings(tmp_path: Path) -> None:
    folder = write_double(tmp_path, "bad", {"test_double.py": CHECK})
    toml = folder / "assignment.toml"
    toml.write_text(toml.read_text() + 'requirements = "pandas"\n')
    with pytest.raises(AssignmentError, match=r"\[assignment\] requirements must be a list"):
        load_assignment(folder)


def test_every_runner_meets_the_check_through_grader_grade(tmp_path: Path) -> None:
    """The service, Dask and Gradescope call ``Grader.grade`` directly: it checks too."""
    from autograder.engine.grader import Grader

    folder = _assignment(tmp_path, ["numgrade-no-such-package>=1"])
    path = submission(tmp_path / "subs", "alice", RIGHT)
    with Grader(load_assignment(folder)) as grader:
        with pytest.raises(AssignmentError, match="needs 'numgrade-no-such-package>=1'"):
            grader.grade(path, out_dir=tmp_path / "out" / "alice")
    assert _nothing_written(tmp_path / "out")
