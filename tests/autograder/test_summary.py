"""The class summary, checked against a batch with a known mix of scores (no grading)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping
from pathlib import Path

import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import GradingOptions, submission_key
from autograder.engine.submission import file_sha256 as _file_sha256
from autograder.results.model import CheckResult, SubmissionResult
from autograder.results.store import write_result
from autograder.results.summary import (
    histogram,
    summarise,
    suspected_hard_coding,
    unseen_checks,
    write_summary,
)
from autograder.runners.batch import grade_batch

ROOT = Path(__file__).resolve().parents[2]

# name: (max points, hidden, dataset)
CHECKS = {"p1": (1, False, None), "p2": (1, False, None), "h[random]": (1, True, "random"),
          "h[unseen-a]": (2, True, "unseen-a"), "h[unseen-b]": (2, True, "unseen-b")}


def result(sub_id: str, scores: Mapping[str, float], *, outcome: str = "graded", seconds: float = 1.0,
           kinds: dict[str, str] | None = None) -> SubmissionResult:
    """A result scoring ``scores`` (missing checks score 0; all checks present unless "error")."""
    kinds = kinds or {}
    tests = tuple(
        CheckResult(name, scores.get(name, 0.0), top, f"message of {name}", hidden=hidden,
                    dataset=dataset,
                    kind=kinds.get(name, "ok" if scores.get(name, 0.0) == top else "wrong"))
        for name, (top, hidden, dataset) in CHECKS.items()) if outcome != "error" else ()
    return SubmissionResult(id=sub_id, source=f"{sub_id}.ipynb", assignment="hull", key="k",
                            sha256="s", outcome=outcome,  # type: ignore[arg-type]
                            output=f"{sub_id}: {outcome}", tests=tests, execution_time=seconds,
                            seed=0)


FULL = {"p1": 1, "p2": 1, "h[random]": 1, "h[unseen-a]": 2, "h[unseen-b]": 2}
BATCH = (
    result("full", FULL, seconds=1.0),                                                   # 7/7
    result("half", {"p1": 1, "h[random]": 1, "h[unseen-a]": 1, "h[unseen-b]": 2},
           seconds=2.0, kinds={"h[unseen-a]": "partial"}),                               # 5/7
    result("coder", {"p1": 1, "p2": 1, "h[random]": 1}, seconds=3.0),                    # 3/7
    result("nearly", {"p1": 1, "p2": 1, "h[random]": 1, "h[unseen-a]": 2}, seconds=4.0), # 5/7
    result("broken", {}, outcome="ungradable", seconds=0.5),                             # 0/7
    result("slow", {"p1": 1}, outcome="timeout", seconds=10.0),                          # 1/7
    result("banned", {"p1": 1, "h[random]": 1}, seconds=1.5,
           kinds={"p2": "forbidden", "h[unseen-a]": "forbidden"}),                       # 2/7
    result("oops", {}, outcome="error", seconds=0.0),                                    # no score
)


def test_score_statistics() -> None:
    summary = summarise(BATCH)
    assert summary.submissions == 8 and summary.scored == 7
    assert dict(summary.outcomes) == {"graded": 5, "ungradable": 1, "timeout": 1, "error": 1}
    assert summary.percents == pytest.approx([100, 500 / 7, 300 / 7, 500 / 7, 0, 100 / 7, 200 / 7])
    assert summary.mean_percent == pytest.approx(2300 / 49)
    assert summary.median_percent == pytest.approx(300 / 7)
    assert [b.count for b in summary.histogram] == [1, 1, 1, 0, 1, 0, 0, 2, 0, 1]
    assert summary.mean_seconds == pytest.approx(22 / 7), "grader errors are not timed"


def test_histogram_edges() -> None:
    bins = histogram([0, 9.999999, 10, 99.9, 100])
    assert [b.count for b in bins] == [2, 1, 0, 0, 0, 0, 0, 0, 0, 2]
    assert (bins[0].low, bins[-1].high) == (0, 100)


def test_checks_hardest_first() -> None:
    checks = summarise(BATCH).checks
    assert [c.name for c in checks] == ["h[unseen-b]", "h[unseen-a]", "p2", "h[random]", "p1"]
    rates = {c.name: (c.passed, c.submissions) for c in checks}
    assert rates == {"h[unseen-b]": (2, 7), "h[unseen-a]": (2, 7), "p2": (3, 7),
                     "h[random]": (5, 7), "p1": (6, 7)}
    assert checks[1].mean_fraction == pytest.approx(2.5 / 7) and checks[0].hidden


def test_who_needs_a_person() -> None:
    attention = summarise(BATCH).attention
    assert [(a.id, [c.kind for c in a.concerns]) for a in attention] == [
        ("oops", ["error"]), ("broken", ["ungradable"]), ("slow", ["timeout"]),
        ("banned", ["forbidden"]), ("coder", ["hard-coding"])]
    banned = attention[3].concerns[0].detail
    assert banned.startswith("p2, h[unseen-a]: message of p2")


def test_hard_coding_rule() -> None:
    coder, nearly, half = BATCH[2], BATCH[3], BATCH[1]
    assert [c.name for c in unseen_checks(coder)] == ["h[unseen-a]", "h[unseen-b]"]
    assert suspected_hard_coding(coder)
    assert not suspected_hard_coding(nearly), "passing one unseen dataset clears it"
    assert not suspected_hard_coding(half), "failing a public check clears it"
    partial = result("partial", {"p1": 1, "p2": 1, "h[random]": 1, "h[unseen-a]": 1},
                     kinds={"h[unseen-a]": "partial"})
    assert suspected_hard_coding(partial), "partial credit on unseen data is a failure"


def test_without_unseen_datasets_all_hidden_checks_count() -> None:
    tests = (CheckResult("pub", 1, 1, "", hidden=False),
             CheckResult("hid[a]", 0, 1, "", hidden=True, kind="wrong", dataset="a"),
             CheckResult("hid[b]", 0, 1, "", hidden=True, kind="wrong", dataset=None))
    flagged = SubmissionResult(id="x", source="", assignment="a", key="", sha256="",
                               outcome="graded", output="", tests=tests, execution_time=0, seed=0)
    assert [c.name for c in unseen_checks(flagged)] == ["hid[a]", "hid[b]"]
    assert suspected_hard_coding(flagged)
    cleared = flagged.with_tests(tests[:2] + (CheckResult("hid[b]", 1, 1, "", hidden=True),))
    assert not suspected_hard_coding(cleared)
    assert not suspected_hard_coding(flagged.with_tests(tests[1:])), "needs a public check"


def test_files_written(tmp_path: Path) -> None:
    summary = write_summary(tmp_path, BATCH, title="Convex hull")
    data = json.loads((tmp_path / "summary.json").read_text())
    assert data == json.loads(json.dumps(summary.to_dict()))
    assert data["mean_percent"] == pytest.approx(2300 / 49, abs=1e-3)
    assert data["checks"][0]["name"] == "h[unseen-b]" and "unseen" in data["hard_coding_rule"]
    html = (tmp_path / "summary.html").read_text()
    assert 'href="coder/feedback.html"' in html and "suspected hard-coding" in html
    assert "<svg" in html and html.count('class="bar"') == 10
    assert "<script" not in html and "Convex hull: class summary" in html


def test_empty_batch_has_a_summary(tmp_path: Path) -> None:
    summary = write_summary(tmp_path, [])
    assert summary.mean_percent is None and summary.checks == ()
    assert "–%" in (tmp_path / "summary.html").read_text()


def test_batch_writes_summary_and_pages_from_reused_results(tmp_path: Path) -> None:
    """grade_batch writes the summary from every result, reused ones included."""
    assignment = load_assignment(ROOT / "assignments" / "hull")
    submissions = tmp_path / "submitted"
    submissions.mkdir()
    out = tmp_path / "out"
    for stem, (scores, outcome) in {"ann": (FULL, "graded"), "ben": ({}, "ungradable")}.items():
        notebook = submissions / f"{stem}.ipynb"
        shutil.copy(ROOT / "assignments" / "hull" / "examples" / "solution.ipynb", notebook)
        notebook.write_text(notebook.read_text() + " " * len(stem))  # distinct files
        key = submission_key(_file_sha256(notebook), assignment, GradingOptions())
        stored = result(stem, scores, outcome=outcome)
        write_result(out / stem, SubmissionResult(**{**stored.__dict__, "key": key}))
    report = grade_batch(assignment, [submissions], out, jobs=1, progress=False)
    assert (report.graded, report.reused) == (0, 2)
    data = json.loads((out / "summary.json").read_text())
    assert data["submissions"] == 2 and data["outcomes"] == {"graded": 1, "ungradable": 1}
    assert [a["id"] for a in data["attention"]] == ["ben"]
    assert (out / "ann" / "feedback.html").exists() and (out / "ben" / "feedback.html").exists()
    assert f"{assignment.title}: class summary" in (out / "summary.html").read_text()
