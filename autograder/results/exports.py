"""Results for other systems: JUnit XML, CI output (GitHub Classroom), the Gradescope zip.

Each export is computed from :class:`~autograder.results.model.SubmissionResult`
objects (or, for the zip, from an assignment folder and this package's
source); none of them grades anything. Running a submission the Gradescope way
is :func:`autograder.api.gradescope_run`.
"""

from __future__ import annotations

import base64
import json
import re
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Sequence
from pathlib import Path

from autograder.results.feedback import clean_text
from autograder.results.files import atomic_write_text
from autograder.results.model import CheckResult, SubmissionResult
from autograder.results.summary import CONCERNS, summarise

# -- JUnit XML --------------------------------------------------------------------

# Characters XML 1.0 cannot hold, even escaped (control characters, lone surrogates, ...).
_NOT_XML = re.compile("[^\t\n\r\u0020-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")


def xml_text(text: str) -> str:
    """``text`` without terminal colour codes and the characters XML 1.0 forbids.

    Student output may hold any of them; ElementTree would write them as they are
    and the file would not parse.
    """
    return _NOT_XML.sub("", clean_text(text))


def _first_line(text: str, limit: int = 300) -> str:
    line = next((part.strip() for part in text.splitlines() if part.strip()), "")
    return line if len(line) <= limit else line[:limit - 1] + "…"


def _testcase(suite: ET.Element, result: SubmissionResult, check: CheckResult) -> str | None:
    """Add one ``<testcase>``; return "failure", "error" or None (passed)."""
    case = ET.SubElement(suite, "testcase", classname=f"{result.assignment}.{result.id}",
                         name=xml_text(check.name), time="0")
    if check.status == "passed":
        return None
    tag = "error" if check.kind == "check-error" else "failure"
    message = xml_text(_first_line(check.output) or f"{check.kind}: {check.score:g}/{check.max_score:g} points")
    node = ET.SubElement(case, tag, message=message, type=check.kind)
    node.text = xml_text(f"{check.output}\n\nscore {check.score:g}/{check.max_score:g}".strip())
    return tag


def _testsuite(parent: ET.Element, result: SubmissionResult) -> tuple[int, int, int]:
    """Add one ``<testsuite>`` for ``result``; return its (tests, failures, errors)."""
    suite = ET.SubElement(parent, "testsuite", name=xml_text(result.id))
    properties = ET.SubElement(suite, "properties")
    for key, value in (("score", f"{result.score:g}"), ("max_score", f"{result.max_score:g}"),
                       ("outcome", result.outcome), ("source", result.source)):
        ET.SubElement(properties, "property", name=key, value=xml_text(value))
    kinds = [_testcase(suite, result, check) for check in result.tests]
    if result.outcome == "error":  # the grader failed: no checks ran
        case = ET.SubElement(suite, "testcase", classname=f"{result.assignment}.{result.id}",
                             name="grading", time="0")
        ET.SubElement(case, "error", message=xml_text(_first_line(result.output)),
                      type="grader-error").text = xml_text(result.output)
        kinds.append("error")
    counts = (len(kinds), kinds.count("failure"), kinds.count("error"))
    suite.set("tests", str(counts[0]))
    suite.set("failures", str(counts[1]))
    suite.set("errors", str(counts[2]))
    suite.set("skipped", "0")
    suite.set("time", f"{result.execution_time:.3f}")
    return counts


def junit_xml(results: Sequence[SubmissionResult], *, name: str = "") -> str:
    """JUnit XML: one ``<testsuite>`` per submission, one ``<testcase>`` per check.

    A check without full marks is a ``<failure>`` whose ``message`` is the first
    line of the check's message; a check that broke (kind ``check-error``) and a
    submission the grader failed on (outcome ``error``) are ``<error>`` elements.
    """
    root = ET.Element("testsuites", name=xml_text(name or "autograder"))
    totals = [0, 0, 0]
    for result in results:
        for k, n in enumerate(_testsuite(root, result)):
            totals[k] += n
    root.set("tests", str(totals[0]))
    root.set("failures", str(totals[1]))
    root.set("errors", str(totals[2]))
    root.set("time", f"{sum(r.execution_time for r in results):.3f}")
    ET.indent(root)
    return ET.tostring(root, encoding="unicode", xml_declaration=True) + "\n"


def write_junit(path: Path, results: Sequence[SubmissionResult], *, name: str = "") -> Path:
    """Write :func:`junit_xml` to ``path`` atomically."""
    atomic_write_text(Path(path), junit_xml(results, name=name))
    return Path(path)


# -- CI: GitHub Classroom and the step summary --------------------------------------

def points_line(result: SubmissionResult) -> str:
    """``Points X/Y``: the line GitHub Classroom's reporter reads from a job's log."""
    return f"Points {result.score:g}/{result.max_score:g}"


def ci_lines(results: Iterable[SubmissionResult]) -> list[str]:
    """Two lines per submission: its id and outcome, then its ``Points X/Y`` line."""
    lines: list[str] = []
    for result in results:
        lines += [f"Submission {result.id} ({result.outcome})", points_line(result)]
    return lines


def _md(text: str) -> str:
    """``text`` safe inside a Markdown table cell or list item (no HTML, no pipes, one line)."""
    text = " ".join(str(text).split())
    for char, escaped in (("&", "&amp;"), ("<", "&lt;"), (">", "&gt;"), ("|", "\\|"),
                          ("`", "\\`"), ("*", "\\*"), ("[", "\\["), ("]", "\\]")):
        text = text.replace(char, escaped)
    return text


def step_summary_markdown(results: Sequence[SubmissionResult], *, title: str = "",
                          hardest: int = 5) -> str:
    """A Markdown report of a batch for ``$GITHUB_STEP_SUMMARY``."""
    summary = summarise(results)
    mean = "–" if summary.mean_percent is None else f"{summary.mean_percent:.1f}%"
    counts = (f"{summary.submissions} submission(s); mean score {mean}; "
              f"{len(summary.attention)} need a person.")
    lines = [f"## Autograder: {_md(title or summary.assignment)}", "", counts, "",
             "| submission | points | % | outcome |", "|---|---:|---:|---|"]
    for result in sorted(results, key=lambda r: r.id):
        pct = 100 * result.score / result.max_score if result.max_score else 0.0
        lines.append(f"| {_md(result.id)} | {result.score:g}/{result.max_score:g} | {pct:.0f} "
                     f"| {_md(result.outcome)} |")
    if summary.attention:
        lines += ["", "### Needs a person", ""]
        for item in summary.attention:
            why = "; ".join(f"{CONCERNS.get(c.kind, c.kind)}: {c.detail}" for c in item.concerns)
            lines.append(f"- **{_md(item.id)}**: {_md(why)}")
    if summary.checks:
        lines += ["", "### Hardest checks", "", "| check | passed |", "|---|---:|"]
        for check in summary.checks[:hardest]:
            lines.append(f"| {_md(check.name)}{' (hidden)' if check.hidden else ''} "
                         f"| {check.passed}/{check.submissions} |")
    return "\n".join(lines) + "\n"


def append_step_summary(path: Path, results: Sequence[SubmissionResult], *, title: str = "") -> None:
    """Append :func:`step_summary_markdown` to ``path`` (GitHub Actions' ``$GITHUB_STEP_SUMMARY``)."""
    with open(path, "a", encoding="utf-8") as handle:
        handle.write(step_summary_markdown(results, title=title) + "\n")


# -- Gradescope's results.json -------------------------------------------------------

def write_gradescope_result(out: Path, result: SubmissionResult) -> Path:
    """``out/results.json`` for Gradescope, with each check's pictures inside its output.

    Gradescope shows only ``results.json``, not the files beside it, so a picture
    attached to a check (the student's car beside the reference) is embedded as a
    data URI in the test's Markdown output.
    """
    data = result.to_dict()
    for test, entry in zip(result.tests, data["tests"]):
        pictures = []
        for attachment in test.attachments:
            try:  # attachments are named relative to the result's folder
                png = (out / attachment.filename).read_bytes()
            except OSError:
                continue
            label = clean_text(attachment.label).replace("]", " ")
            pictures.append(f"![{label}](data:image/png;base64,{base64.b64encode(png).decode()})")
        if pictures:
            entry["output"] = (entry["output"] + "\n\n" + "\n\n".join(pictures)).strip()
            entry["output_format"] = "md"
    path = out / "results.json"
    atomic_write_text(path, json.dumps(data, indent=2, ensure_ascii=False))
    return path


__all__ = ["append_step_summary", "ci_lines", "junit_xml", "points_line", "step_summary_markdown",
           "write_gradescope_result", "write_junit", "xml_text"]
