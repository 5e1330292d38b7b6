"""The feedback page's content, and that every graded file gets one (no browser here)."""

from __future__ import annotations

import base64
import re
from pathlib import Path
from typing import Any

import pytest

from autograder.results.feedback import FEEDBACK_NAME, clip, render_feedback, write_feedback
from autograder.results.model import Attachment, CellError, CheckResult, SubmissionResult
from autograder.results.store import read_result, write_result
from autograder.results.store import refresh_feedback, write_submission
from autograder.runners.local import grade_one

PNG = base64.b64decode(  # a 1x1 PNG
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5ErkJggg==")


def make_result(**changes: Any) -> SubmissionResult:
    tests = (
        CheckResult("orientation[turns]", 1, 1, "", hidden=False, dataset="turns"),
        CheckResult("draw_car", 1, 2, "The wheels are <b>off</b> by 4%.", hidden=False,
                    kind="partial", attachments=(Attachment("your car", "images/car.png"),)),
        CheckResult("convex_hull[unseen-circle]", 0, 2, "Expected 12 vertices, got 11.",
                    hidden=True, kind="wrong", dataset="unseen-circle",
                    attachments=(Attachment("unseen", "images/unseen.png"),)),
    )
    base: dict[str, Any] = {
        "id": "alice", "source": "alice.ipynb", "assignment": "hull", "key": "k",
        "sha256": "0" * 64, "outcome": "graded", "tests": tests, "execution_time": 0.5, "seed": 3,
        "output": "Your notebook's 3 code cell(s) ran in 0.1 s."}
    base.update(changes)
    return SubmissionResult(**base)


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    folder = tmp_path / "alice"
    (folder / "images").mkdir(parents=True)
    (folder / "images" / "car.png").write_bytes(PNG)
    (folder / "images" / "unseen.png").write_bytes(PNG + b"unseen")
    return folder


def test_page_is_self_contained(folder: Path) -> None:
    html = write_feedback(folder, make_result(), title="Convex hull").read_text()
    assert "data:image/png;base64," + base64.b64encode(PNG).decode() in html
    assert not re.search(r"""(src|href)=["'](?!data:)""", html), "nothing may load from outside"
    assert "http://" not in html and "https://" not in html and "<script" not in html
    assert "default-src 'none'" in html
    assert "1 / 2 points" in html and ">2 / 5<" in html
    assert "@media print" in html and "@media (max-width" in html


def test_untrusted_text_is_escaped(folder: Path) -> None:
    result = make_result(stdout="</pre><script>alert(1)</script>",
                         cell_errors=(CellError(0, "ValueError", "<img src=x onerror=alert(1)>",
                                                "\x1b[31mValueError\x1b[0m: <bad>"),))
    html = render_feedback(folder, result)
    assert "<b>off</b>" not in html and "&lt;b&gt;off&lt;/b&gt;" in html
    assert "<script>alert" not in html and "&lt;/pre&gt;&lt;script&gt;" in html
    assert "<img src=x" not in html
    assert "\x1b" not in html and "ValueError: &lt;bad&gt;" in html
    assert "Cell 1" in html  # cells are numbered from 1, as the grader's summary does


def test_hidden_checks_show_status_points_and_message_never_pictures(folder: Path) -> None:
    passed = CheckResult("convex_hull[unseen-tiny]", 1, 1, "", hidden=True,
                         dataset="unseen-tiny")
    result = make_result(tests=make_result().tests + (passed,))
    html = render_feedback(folder, result)
    assert "convex_hull[unseen-circle]" in html and "Expected 12 vertices, got 11." in html
    assert base64.b64encode(PNG + b"unseen").decode() not in html, "no picture of unseen data"
    hidden = html[html.index("Hidden checks"):]
    assert "1 of 3 points together" in hidden
    failed = hidden[hidden.index("convex_hull[unseen-circle]"):hidden.index("unseen-tiny")]
    assert "0 / 2 points" in failed and "wrong answer" in failed and "badge failed" in failed
    assert "it is not shown here" in failed, "a picture the page does not show is named as such"
    ok = hidden[hidden.index("convex_hull[unseen-tiny]"):]
    assert "1 / 1 points" in ok and "passed" in ok and "not shown here" not in ok


def test_long_output_is_cut_and_says_so() -> None:
    text = "\n".join(f"line {k}" for k in range(1000))
    cut = clip(text, max_lines=50, max_chars=10_000)
    assert cut.startswith("line 0\n") and "line 49\n" in cut and "line 50\n" not in cut
    assert "950 line(s) not shown" in cut
    tail = clip(text, max_lines=50, max_chars=10_000, tail_lines=10)
    assert tail.endswith("line 999") and "line 989" not in tail and "line 990" in tail
    assert clip("x" * 500, max_lines=5, max_chars=100).endswith("400 character(s) not shown ...]")


def test_pictures_outside_the_folder_or_missing_are_named_not_shown(tmp_path: Path, folder: Path) -> None:
    (tmp_path / "secret.png").write_bytes(PNG + b"secret")
    check = CheckResult("figure", 0, 1, "", hidden=False, kind="wrong",
                        attachments=(Attachment("escape", "../secret.png"),
                                     Attachment("gone", "images/gone.png"),
                                     Attachment("text", "images/notes.txt")))
    (folder / "images" / "notes.txt").write_text("<svg onload=alert(1)>")
    html = render_feedback(folder, make_result(tests=(check,)))
    assert base64.b64encode(PNG + b"secret").decode() not in html
    assert "outside the results folder" in html and "missing" in html
    assert "not a PNG, JPEG or GIF" in html


@pytest.mark.parametrize("outcome", ["ungradable", "timeout", "crashed", "error"])
def test_every_outcome_gets_a_page(tmp_path: Path, outcome: str) -> None:
    result = make_result(outcome=outcome, output="This file could not be graded: not JSON.",
                         tests=() if outcome == "error" else make_result().tests)
    html = write_feedback(tmp_path, result).read_text()
    assert "This file could not be graded: not JSON." in html
    assert f'<span class="badge error">{outcome}</span>' in html
    if outcome == "error":
        assert "not final" in html


class FakeGrader:
    """Stands in for :class:`autograder.engine.grader.Grader` in ``grade_one``."""

    class assignment:  # mimics Grader.assignment
        name = "hull"
        title = "Convex hull"

    def __init__(self, fail: bool) -> None:
        self.fail = fail

    def grade(self, path: Path, *, id: str, out_dir: Path) -> SubmissionResult:
        if self.fail:
            raise RuntimeError("the grader broke")
        result = make_result(id=id, tests=make_result().tests[:1])
        return write_submission(out_dir, result, title=self.assignment.title)  # as Grader.grade


@pytest.mark.parametrize("fail", [False, True])
def test_grade_one_writes_the_page_after_results(tmp_path: Path, fail: bool) -> None:
    notebook = tmp_path / "bob.ipynb"
    notebook.write_text("{}")
    result = grade_one(FakeGrader(fail), notebook, "bob", tmp_path / "out")  # type: ignore[arg-type]
    folder = tmp_path / "out" / "bob"
    page = folder / FEEDBACK_NAME
    assert page.exists() and read_result(folder) == result
    assert page.stat().st_mtime_ns >= (folder / "results.json").stat().st_mtime_ns
    assert result.outcome == ("error" if fail else "graded")
    assert "Convex hull" in page.read_text()


def test_reused_results_get_a_missing_page(tmp_path: Path) -> None:
    result = make_result(tests=make_result().tests[:1])
    write_result(tmp_path, result)
    refresh_feedback(tmp_path, result, title="Convex hull")
    page = tmp_path / FEEDBACK_NAME
    assert page.exists()
    page.write_text("kept")
    refresh_feedback(tmp_path, result, title="Convex hull")
    assert page.read_text() == "kept", "an up-to-date page is not rewritten"
