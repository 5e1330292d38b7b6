"""Results for other systems: JUnit XML, CI output (GitHub Classroom), the Gradescope zip.

Each export is computed from :class:`~autograder.results.SubmissionResult`
objects (or, for the zip, from an assignment folder and this package's
source); none of them grades anything. Running a submission the Gradescope way
is :func:`autograder.api.gradescope_run`.
"""

from __future__ import annotations

import base64
import importlib.resources
import io
import json
import re
import xml.etree.ElementTree as ET
import zipfile
from collections.abc import Iterable, Sequence
from pathlib import Path

import nbformat

import autograder
from autograder.assignment import Assignment
from autograder.errors import UsageError
from autograder.feedback import clean_text
from autograder.report import atomic_write_text
from autograder.results import CheckResult, SubmissionResult
from autograder.summary import CONCERNS, summarise

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


# -- Gradescope ------------------------------------------------------------------------

#: where Gradescope puts things; every path below it can be moved with this variable
ROOT_ENV = "AUTOGRADER_ROOT"
GRADESCOPE_ROOT = Path("/autograder")
#: the scripts at the top of the zip, and the package templates they come from
GRADESCOPE_SCRIPTS = {"setup.sh": "gradescope_setup.sh", "run_autograder": "gradescope_run_autograder"}
_SKIP_PARTS = {"__pycache__", ".ipynb_checkpoints", ".pytest_cache", ".mypy_cache", ".hypothesis"}
_EPOCH = (1980, 1, 1, 0, 0, 0)


def source_root() -> Path:
    """The checkout this package runs from (``pyproject.toml``, ``autograder/``, ``reference/``)."""
    root = Path(autograder.__file__).resolve().parent.parent
    missing = [n for n in ("pyproject.toml", "README.md", "autograder", "reference",
                           "reference/pyproject.toml")
               if not (root / n).exists()]
    if missing:
        raise UsageError(f"The Gradescope zip bundles this package's source, but {root} lacks "
                         f"{', '.join(missing)}; run the command from a source checkout "
                         "(pip install -e .).")
    return root


def _files(folder: Path, *, skip_top: tuple[str, ...] = ()) -> list[Path]:
    def wanted(path: Path) -> bool:
        parts = path.relative_to(folder).parts
        return (path.is_file() and path.suffix != ".pyc" and parts[0] not in skip_top
                and not any(q in _SKIP_PARTS or q.endswith(".egg-info") for q in parts))
    return sorted(p for p in folder.rglob("*") if wanted(p))


def gradescope_entries(assignment: Assignment) -> list[tuple[str, Path | bytes, bool]]:
    """What the zip holds: (name in the zip, file or bytes, executable), in zip order.

    The two scripts at the top, then ``pyproject.toml``, ``README.md``,
    ``autograder/`` and ``reference/`` (installed by ``setup.sh``), then the
    assignment under ``assignment/<name>/`` with its hidden checks and without
    its sample submissions (``examples/``).
    """
    root = source_root()
    templates = importlib.resources.files("autograder") / "templates"
    entries: list[tuple[str, Path | bytes, bool]] = [
        (name, (templates / template).read_bytes(), True)
        for name, template in GRADESCOPE_SCRIPTS.items()]
    entries += [(name, root / name, False) for name in ("pyproject.toml", "README.md")]
    for package in ("autograder", "reference"):
        entries += [(p.relative_to(root).as_posix(), p, False) for p in _files(root / package)]
    # The instructor notebook holds the solutions: the zip carries the released one in
    # its place (the grader needs it only to restore locked cells).
    from autograder.release import student_template  # imports nbgrader: instructors only

    released = nbformat.writes(student_template(assignment)).encode()
    for path in _files(assignment.root, skip_top=("examples",)):
        name = f"assignment/{assignment.name}/{path.relative_to(assignment.root).as_posix()}"
        entries.append((name, released if path == assignment.notebook else path, False))
    return entries


def gradescope_zip(assignment: Assignment, out_dir: Path) -> Path:
    """Write ``out_dir/<name>-gradescope.zip``, the autograder zip Gradescope's settings take.

    The zip is reproducible: entries in a fixed order with a fixed date, so
    the same sources give the same bytes.
    """
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, content, executable in gradescope_entries(assignment):
            info = zipfile.ZipInfo(name, date_time=_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = ((0o100755 if executable else 0o100644) << 16)
            data = content if isinstance(content, bytes) else content.read_bytes()
            archive.writestr(info, data)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{assignment.name}-gradescope.zip"
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(buffer.getvalue())
    tmp.replace(path)
    return path


def bundled_assignment(source: Path) -> Path:
    """The one assignment folder in an unpacked zip (``source/assignment/<name>/``)."""
    found = sorted(p.parent for p in (source / "assignment").glob("*/assignment.toml"))
    if len(found) != 1:
        raise UsageError(f"Expected one assignment under {source / 'assignment'}, found "
                         f"{len(found)}; rebuild the zip with 'autograder gradescope'.")
    return found[0]


def gradescope_student(root: Path) -> str | None:
    """The submitter's id from Gradescope's ``submission_metadata.json`` (seeds unseen data)."""
    try:
        users = json.loads((root / "submission_metadata.json").read_text())["users"]
        first = users[0]
        return str(first.get("sid") or first.get("email") or first.get("name")) or None
    except (OSError, ValueError, KeyError, IndexError, TypeError, AttributeError):
        return None


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


def pick_notebook(folder: Path, expected_name: str) -> tuple[Path, str]:
    """The notebook to grade among a Gradescope submission's files, and a note for the student.

    The file named like the assignment's notebook wins; else the only notebook;
    else the first by name, with a note saying so. With no notebook at all the
    expected path is returned (the grader then reports it missing).
    """
    # Regular files only: a link could point at any file of the image (the bundled
    # assignment, another notebook); the grader refuses one if it is picked anyway.
    notebooks = sorted(p for p in folder.rglob("*.ipynb")
                       if p.is_file() and not p.is_symlink() and ".ipynb_checkpoints" not in p.parts)
    named = [p for p in notebooks if p.name == expected_name]
    if named:
        return named[0], ""
    if len(notebooks) == 1 or not notebooks:
        return (notebooks[0] if notebooks else folder / expected_name), ""
    names = ", ".join(p.name for p in notebooks)
    return notebooks[0], (f"You submitted several notebooks ({names}) and none is named "
                          f"{expected_name}; {notebooks[0].name} was graded.")


__all__ = ["GRADESCOPE_ROOT", "GRADESCOPE_SCRIPTS", "ROOT_ENV", "append_step_summary",
           "bundled_assignment", "ci_lines", "gradescope_student", "write_gradescope_result", "gradescope_entries", "gradescope_zip", "junit_xml",
           "pick_notebook", "points_line", "source_root", "step_summary_markdown", "write_junit",
           "xml_text"]
