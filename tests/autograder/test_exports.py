"""Exports for other systems: JUnit XML, the --ci output, the Gradescope zip run as Gradescope runs it."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest

from autograder import api, cli
from autograder.authoring.gradescope import pick_notebook
from autograder.results.exports import ci_lines, junit_xml, points_line, step_summary_markdown
from autograder.results.model import CheckResult, SubmissionResult
from autograder.runners.batch import BatchRun

ROOT = Path(__file__).resolve().parents[2]
HULL = ROOT / "assignments" / "hull"
EXAMPLES = HULL / "examples"


def make(sub_id: str, checks: list[tuple[str, float, float, str, str]], *, outcome: str = "graded",
         output: str = "") -> SubmissionResult:
    """A result from (name, score, max, kind, message) tuples."""
    tests = tuple(CheckResult(n, s, m, msg, hidden=False, kind=k) for n, s, m, k, msg in checks)
    return SubmissionResult(id=sub_id, source=f"{sub_id}.ipynb", assignment="hull", key="k",
                            sha256="s", outcome=outcome,  # type: ignore[arg-type]
                            output=output, tests=tests, execution_time=1.25, seed=0)


BATCH = [
    make("alice", [("a", 1, 1, "ok", ""), ("b", 0.5, 1, "partial", "correct but clockwise\nmore")]),
    make("bob", [("a", 0, 1, "exception", "raised \x00\x1b[31mValueError <x> & \ud800"),
                 ("b", 0, 1, "check-error", "the check broke")]),
    make("carol", [], outcome="error", output="The grader failed on this submission (OSError)."),
]


def test_junit_xml_parses_and_counts_match() -> None:
    root = ET.fromstring(junit_xml(BATCH, name="hull").encode())
    assert root.tag == "testsuites" and root.get("name") == "hull"
    assert (root.get("tests"), root.get("failures"), root.get("errors")) == ("5", "2", "2")
    suites = {s.get("name"): s for s in root.findall("testsuite")}
    assert list(suites) == ["alice", "bob", "carol"]
    counts = {n: (s.get("tests"), s.get("failures"), s.get("errors")) for n, s in suites.items()}
    assert counts == {"alice": ("2", "1", "0"), "bob": ("2", "1", "1"), "carol": ("1", "0", "1")}
    failure = suites["alice"].find("testcase[@name='b']/failure")
    assert failure is not None and failure.get("message") == "correct but clockwise"
    assert failure.get("type") == "partial" and "score 0.5/1" in (failure.text or "")
    bob = suites["bob"].find("testcase[@name='a']/failure")
    assert bob is not None and bob.get("message") == "raised ValueError <x> & "
    props = {p.get("name"): p.get("value") for p in suites["alice"].iter("property")}
    assert props == {"score": "1.5", "max_score": "2", "outcome": "graded", "source": "alice.ipynb"}
    assert suites["carol"].find("testcase[@name='grading']/error") is not None


def test_points_lines() -> None:
    assert points_line(BATCH[0]) == "Points 1.5/2"
    assert ci_lines(BATCH) == ["Submission alice (graded)", "Points 1.5/2",
                               "Submission bob (graded)", "Points 0/2",
                               "Submission carol (error)", "Points 0/0"]


def test_step_summary_is_markdown_with_untrusted_text_escaped() -> None:
    hostile = make("dave", [("a|b", 0, 1, "forbidden", "<img src=x> | uses scipy")])
    text = step_summary_markdown([*BATCH, hostile], title="Convex hull")
    assert text.startswith("## Autograder: Convex hull\n")
    assert "| alice | 1.5/2 | 75 | graded |" in text
    assert "### Needs a person" in text and "**carol**" in text
    assert "<img" not in text and "&lt;img src=x&gt; \\| uses scipy" in text
    assert "| a\\|b | 0/1 |" in text


def _fake_grade(results: list[SubmissionResult]):  # type: ignore[no-untyped-def]
    def grade(*args: object, **kwargs: object) -> BatchRun:
        return BatchRun(results=tuple(results), graded=len(results), reused=0, seconds=0.1)
    return grade


@pytest.mark.parametrize("with_error", [False, True])
def test_ci_exit_status_only_fails_when_grading_failed(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path,
        with_error: bool) -> None:
    summary = tmp_path / "step-summary.md"
    summary.write_text("earlier step\n")
    monkeypatch.setenv("GITHUB_STEP_SUMMARY", str(summary))
    batch = BATCH if with_error else BATCH[:2]  # low scores alone never fail the run
    monkeypatch.setattr(api, "grade", _fake_grade(batch))
    status = cli.main(["grade", "hull", str(EXAMPLES), "--out", str(tmp_path / "out"), "--ci"])
    out = capsys.readouterr().out
    assert status == (1 if with_error else 0)
    assert [line for line in out.splitlines() if line.startswith("Points ")] == \
        [points_line(r) for r in batch]
    text = summary.read_text()
    assert text.startswith("earlier step\n## Autograder: hull\n"), "appended, never replaced"


@pytest.mark.slow
def test_ci_run_end_to_end(tmp_path: Path) -> None:
    out, junit, summary = tmp_path / "out", tmp_path / "junit.xml", tmp_path / "summary.md"
    proc = subprocess.run(
        [sys.executable, "-m", "autograder", "grade", "hull", str(EXAMPLES / "wrong-clockwise.ipynb"),
         str(EXAMPLES / "partial-only-orientation.ipynb"), "--out", str(out), "--jobs", "2",
         "--ci", "--junit", str(junit)],
        capture_output=True, text=True, check=False, timeout=300,
        # A CI job's own pytest settings must not reach the grader's check runs.
        env={**os.environ, "GITHUB_STEP_SUMMARY": str(summary),
             "PYTEST_ADDOPTS": f"--junitxml={tmp_path / 'outer.xml'} --durations=5",
             "PYTEST_PLUGINS": "a_plugin_that_does_not_exist"})
    assert proc.returncode == 0, proc.stderr
    points = [line for line in proc.stdout.splitlines() if line.startswith("Points ")]
    assert sorted(points) == ["Points 10/38", "Points 27/38"]
    root = ET.parse(junit).getroot()
    for suite in root.findall("testsuite"):
        data = json.loads((out / str(suite.get("name")) / "results.json").read_text())
        assert int(suite.get("tests", "")) == len(data["tests"])
        assert int(suite.get("failures", "")) == sum(t["status"] == "failed" for t in data["tests"])
        assert (out / str(suite.get("name")) / "feedback.html").exists()
    assert len(root.findall("testsuite")) == 2
    assert (out / "summary.html").exists() and (out / "summary.json").exists()
    assert "| wrong-clockwise | 27/38 |" in summary.read_text()


def test_pick_notebook(tmp_path: Path) -> None:
    assert pick_notebook(tmp_path, "hull.ipynb") == (tmp_path / "hull.ipynb", "")
    (tmp_path / "b.ipynb").write_text("{}")
    assert pick_notebook(tmp_path, "hull.ipynb") == (tmp_path / "b.ipynb", "")
    (tmp_path / "a.ipynb").write_text("{}")
    chosen, note = pick_notebook(tmp_path, "hull.ipynb")
    assert chosen == tmp_path / "a.ipynb" and "several notebooks (a.ipynb, b.ipynb)" in note
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "hull.ipynb").write_text("{}")
    assert pick_notebook(tmp_path, "hull.ipynb") == (tmp_path / "sub" / "hull.ipynb", "")


@pytest.fixture(scope="module")
def gradescope_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("zip")
    proc = subprocess.run([sys.executable, "-m", "autograder", "gradescope", "hull", "--out", str(out)],
                          capture_output=True, text=True, check=False, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return out / "hull-gradescope.zip"


def test_zip_layout(gradescope_zip: Path, tmp_path: Path) -> None:
    with zipfile.ZipFile(gradescope_zip) as archive:
        names = set(archive.namelist())
        modes = {i.filename: i.external_attr >> 16 for i in archive.infolist()}
    for required in ("setup.sh", "run_autograder", "pyproject.toml", "README.md",
                     "autograder/__init__.py", "autograder/results/templates/feedback.html.j2",
                     "reference/__init__.py", "assignment/hull/assignment.toml",
                     "assignment/hull/hull.ipynb", "assignment/hull/checks/hidden/test_hull_hidden.py",
                     "assignment/hull/checks/public/test_hull_public.py"):
        assert required in names, required
    assert modes["setup.sh"] & stat.S_IXUSR and modes["run_autograder"] & stat.S_IXUSR
    assert not any("__pycache__" in n or "/examples/" in n for n in names)
    again = api.gradescope("hull", out=tmp_path)
    assert again.read_bytes() == gradescope_zip.read_bytes(), "the zip is reproducible"
    for script in ("setup.sh", "run_autograder"):
        with zipfile.ZipFile(gradescope_zip) as archive:
            (tmp_path / script).write_bytes(archive.read(script))
        assert subprocess.run(["bash", "-n", str(tmp_path / script)], check=False).returncode == 0


@pytest.mark.slow
def test_run_autograder_as_gradescope_does(gradescope_zip: Path, tmp_path: Path) -> None:
    """Unpack to source/, copy run_autograder up a level, run it; setup.sh's pip step is skipped."""
    root = tmp_path / "autograder"
    source, submission, results = root / "source", root / "submission", root / "results"
    for folder in (source, submission, results):
        folder.mkdir(parents=True)
    with zipfile.ZipFile(gradescope_zip) as archive:
        archive.extractall(source)
    shutil.copy(source / "run_autograder", root / "run_autograder")
    (root / "run_autograder").chmod(0o755)
    shutil.copy(EXAMPLES / "wrong-clockwise.ipynb", submission / "wrong-clockwise.ipynb")
    # The current Python with the zip's own copy of the package first on the path.
    env = {**os.environ, "AUTOGRADER_ROOT": str(root), "AUTOGRADER_PYTHON": sys.executable,
           "PYTHONPATH": str(source)}
    where = subprocess.run([sys.executable, "-c", "import autograder; print(autograder.__file__)"],
                           env=env, capture_output=True, text=True, check=False, cwd=tmp_path)
    assert where.stdout.strip() == str(source / "autograder" / "__init__.py")
    proc = subprocess.run([str(root / "run_autograder")], env=env, capture_output=True, text=True, check=False,
                          timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((results / "results.json").read_text())
    assert (data["score"], data["max_score"]) == (27.0, 38.0)
    assert data["extra_data"]["outcome"] == "graded" and data["extra_data"]["id"] == "wrong-clockwise"
    hidden = [t for t in data["tests"] if t["extra_data"]["hidden"]]
    plain = [t for t in hidden if "level" not in t["extra_data"]]
    assert plain and all(t["visibility"] == "after_published" for t in plain)
    # the student's own board (visibility "input"): shown, with the input and not the hull
    board = next(t for t in hidden if t["name"] == "convex_hull_your_pins")
    assert board["visibility"] == "visible" and "your own board" in board["output"]
    assert "expected" not in board["output"].lower()
    for test in data["tests"]:
        assert {"name", "score", "max_score", "status", "visibility"} <= set(test)

    (submission / "wrong-clockwise.ipynb").unlink()  # nothing submitted: still a results.json
    proc = subprocess.run([str(root / "run_autograder")], env=env, capture_output=True, text=True, check=False,
                          timeout=300, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    data = json.loads((results / "results.json").read_text())
    assert data["extra_data"]["outcome"] == "ungradable" and data["score"] == 0
    assert "hull.ipynb" in data["output"]


def test_github_classroom_workflow_example() -> None:
    yaml = pytest.importorskip("yaml", reason="PyYAML reads the workflow example")
    workflow = yaml.safe_load((ROOT / "examples" / "github-classroom" / "grade.yml").read_text())
    steps = workflow["jobs"]["grade"]["steps"]
    uses = [s.get("uses", "").split("@")[0] for s in steps]
    assert uses[:2] == ["actions/checkout", "actions/setup-python"]
    assert "actions/upload-artifact" in uses
    run = " ".join(s.get("run", "") for s in steps)
    assert "pip install" in run and "autograder grade" in run
    assert "--ci" in run and "--junit" in run
    assert "${{" not in run, "inputs reach the shell through env, never pasted into scripts"
