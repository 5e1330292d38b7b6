"""The student's feedback page: ``<id>/feedback.html``, one self-contained file.

The page is rendered from ``templates/feedback.html.j2`` with autoescaping on
(messages, tracebacks and printed output come from the student's code and are
untrusted text). Pictures attached to checks are embedded as ``data:`` URIs
and the styles are inline, so the file opens from disk with no network; a
Content-Security-Policy in the page forbids scripts and remote loads.

What a student sees:

* the score, and the grader's summary of how the notebook ran;
* every public check with its status, points, message and pictures (for a
  figure check: the student's drawing beside the reference's);
* hidden checks by name, status, points and message (never their data, code or
  pictures: a picture of an unseen dataset would show the dataset; when a
  hidden check made one, the page says that it is not shown);
* the cells that raised, with their tracebacks, and the notebook's printed
  output, both cut to a readable length;
* for an assignment of several notebooks, one section per notebook (its
  checks and cell errors, its points), and the points waiting for a person.
"""

from __future__ import annotations

import base64
import datetime as dt
import functools
import re
import struct
from dataclasses import dataclass, replace
from pathlib import Path

import jinja2

from autograder.results.files import atomic_write_text
from autograder.results.model import Attachment, CellError, CheckResult, SubmissionResult

FEEDBACK_NAME = "feedback.html"
#: printed output shown on the page (the head is kept: it is what the notebook printed first)
MAX_OUTPUT_LINES = 200
MAX_OUTPUT_CHARS = 20_000
#: a traceback keeps its first and last lines (the last ones name the error)
MAX_TRACEBACK_LINES = 80
#: pictures larger than this are named but not embedded
MAX_PICTURE_BYTES = 4 * 1024 * 1024

_ANSI = re.compile(r"\x1b\[[0-9;?]*[ -/]*[@-~]|\x1b[@-_]")
_CONTROL = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")
_MAGIC = {b"\x89PNG\r\n\x1a\n": "image/png", b"\xff\xd8\xff": "image/jpeg", b"GIF8": "image/gif"}

#: what a failed check's ``kind`` means, in the student's words
KIND_LABELS = {
    "ok": "passed", "wrong": "wrong answer", "partial": "partial credit",
    "exception": "your code raised an error", "missing": "function missing",
    "timeout": "took too long", "not-run": "not run (an earlier input ran out of time)",
    "unsupported": "answer could not be checked",
    "crashed": "your code stopped the worker", "forbidden": "uses something not allowed",
    "check-error": "the check could not use your answer",
    "needs-person": "waits for a person",
    "graded-by-person": "graded by a person", "override": "set by the instructor",
}


@functools.cache
def template_environment() -> jinja2.Environment:
    """The Jinja2 environment for every page: package templates, autoescape always on.

    ``select_autoescape`` would not escape ``*.html.j2`` names, so autoescape is
    forced on; ``StrictUndefined`` turns a misspelt variable into an error.
    """
    return jinja2.Environment(loader=jinja2.PackageLoader("autograder.results.model", "templates"),
                              autoescape=True, undefined=jinja2.StrictUndefined,
                              trim_blocks=True, lstrip_blocks=True)


def clean_text(text: str) -> str:
    """``text`` without terminal colour codes and control characters (tabs and newlines kept)."""
    return _CONTROL.sub("", _ANSI.sub("", text))


def clip(text: str, *, max_lines: int, max_chars: int, tail_lines: int = 0) -> str:
    """``text`` cut to ``max_lines`` lines and ``max_chars`` characters, saying what was cut.

    The first lines are kept, plus the last ``tail_lines`` lines when given
    (a traceback's end names the error).
    """
    lines = text.splitlines()
    if len(lines) > max_lines:
        head = lines[:max_lines - tail_lines]
        tail = lines[len(lines) - tail_lines:] if tail_lines else []
        cut = len(lines) - len(head) - len(tail)
        lines = [*head, f"[... {cut} line(s) not shown ...]", *tail]
    out = "\n".join(lines)
    if len(out) > max_chars:
        out = out[:max_chars] + f"\n[... {len(out) - max_chars} character(s) not shown ...]"
    return out


@dataclass(frozen=True)
class Picture:
    """An attachment ready for the page: a ``data:`` URI, or why it is not shown."""

    label: str
    uri: str | None
    width: int | None = None
    height: int | None = None
    problem: str = ""


def embed_picture(folder: Path, attachment: Attachment) -> Picture:
    """Read ``folder/attachment.filename`` into a ``data:`` URI (PNG, JPEG or GIF only)."""
    root = folder.resolve()
    path = (root / attachment.filename).resolve()
    if not path.is_relative_to(root):
        return Picture(attachment.label, None, problem="the picture lies outside the results folder")
    try:
        data = path.read_bytes()
    except OSError:
        return Picture(attachment.label, None, problem="the picture file is missing")
    if len(data) > MAX_PICTURE_BYTES:
        return Picture(attachment.label, None, problem="the picture is too large to show")
    mime = next((m for magic, m in _MAGIC.items() if data.startswith(magic)), None)
    if mime is None:
        return Picture(attachment.label, None, problem="the file is not a PNG, JPEG or GIF picture")
    width, height = _png_size(data) if mime == "image/png" else (None, None)
    uri = f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"
    return Picture(attachment.label, uri, width, height)


def _png_size(data: bytes) -> tuple[int | None, int | None]:
    if len(data) < 24 or data[12:16] != b"IHDR":
        return None, None
    width, height = struct.unpack(">II", data[16:24])
    return int(width), int(height)


def check_status(check: CheckResult) -> str:
    """``passed``, ``partial`` (some points) or ``failed``: the page's CSS class for a check."""
    if check.status == "passed":
        return "passed"
    return "partial" if check.score > 0 else "failed"


def _public_view(folder: Path, check: CheckResult) -> dict[str, object]:
    status = check_status(check)
    label = "passed" if status == "passed" else KIND_LABELS.get(check.kind, check.kind)
    return {"name": check.name, "status": status, "label": label,
            "score": f"{check.score:g}", "max_score": f"{check.max_score:g}",
            "message": clean_text(check.output),
            "pictures": [embed_picture(folder, a) for a in check.attachments]}


def _hidden_view(check: CheckResult) -> dict[str, object]:
    """Status, points and message of a hidden check: never its data, code or pictures."""
    status = check_status(check)
    label = "passed" if status == "passed" else KIND_LABELS.get(check.kind, check.kind)
    return {"name": check.name, "status": status, "label": label,
            "score": f"{check.score:g}", "max_score": f"{check.max_score:g}",
            "message": clean_text(check.output),
            "pictures_withheld": len(check.attachments)}


def _section(folder: Path, name: str | None, checks: list[CheckResult],
             errors: list[CellError]) -> dict[str, object]:
    """One notebook's part of the page (the whole page when an assignment has one)."""
    public = [c for c in checks if not c.hidden]
    hidden = [c for c in checks if c.hidden]
    return {"name": name, "points": _points(checks),
            "public": [_public_view(folder, c) for c in public], "public_points": _points(public),
            "hidden": [_hidden_view(c) for c in hidden], "hidden_points": _points(hidden),
            "cell_errors": [_error_view(e) for e in errors]}


def _error_view(e: CellError) -> dict[str, object]:
    return {"cell": e.cell + 1, "ename": clean_text(e.ename),
            "evalue": clip(clean_text(e.evalue), max_lines=5, max_chars=500),
            "traceback": clip(clean_text(e.traceback), max_lines=MAX_TRACEBACK_LINES,
                              max_chars=MAX_OUTPUT_CHARS, tail_lines=40)}


def sections(folder: Path, result: SubmissionResult) -> list[dict[str, object]]:
    """The page's sections: one per notebook of a several-notebook assignment, else one."""
    names = list(dict.fromkeys([c.notebook for c in result.tests if c.notebook]
                               + [e.notebook for e in result.cell_errors if e.notebook]))
    if not names:
        return [_section(folder, None, list(result.tests), list(result.cell_errors))]
    loose = [c for c in result.tests if not c.notebook]  # none today; never dropped
    found = [_section(folder, n, [c for c in result.tests if c.notebook == n],
                      [e for e in result.cell_errors if e.notebook == n]) for n in names]
    return found + ([_section(folder, "other checks", loose, [])] if loose else [])


def feedback_context(folder: Path, result: SubmissionResult, *, title: str | None = None
                     ) -> dict[str, object]:
    """Everything the template shows, computed from ``result`` (pictures read from ``folder``)."""
    public = [c for c in result.tests if not c.hidden]
    hidden = [c for c in result.tests if c.hidden]
    percent = 100 * result.score / result.max_score if result.max_score else 0.0
    waiting = sum(c.max_score for c in result.tests if c.kind == "needs-person")
    return {
        "sections": sections(folder, result), "person_points": f"{waiting:g}" if waiting else "",
        "title": title or result.assignment, "id": result.id, "outcome": result.outcome,
        "score": f"{result.score:g}", "max_score": f"{result.max_score:g}",
        "percent": f"{percent:.0f}", "summary": clean_text(result.output),
        "public": [_public_view(folder, c) for c in public],
        "public_points": _points(public),
        "hidden": [_hidden_view(c) for c in hidden], "hidden_points": _points(hidden),
        "cell_errors": [_error_view(e) for e in result.cell_errors],
        "stdout": clip(clean_text(result.stdout), max_lines=MAX_OUTPUT_LINES,
                       max_chars=MAX_OUTPUT_CHARS),
        "engine": result.engine, "sha256": result.sha256[:12], "seed": result.seed,
        "seconds": f"{result.execution_time:.1f}", "kind_labels": KIND_LABELS,
    }


#: what replaces a check's message at each visibility level (None: the message itself)
_LEVEL_NOTES = {"hidden": "Details of this check are not shown.",
                "after_deadline": "Details of this check are shown after the deadline."}


def as_students_see(result: SubmissionResult, *, past_deadline: bool) -> SubmissionResult:
    """``result`` cut to what a student may see of each check's visibility level.

    ``hidden``: name, status and points; ``after_deadline``: the same until the
    deadline, then in full; ``input``: the input the check described, never its
    message (which may hold the expected value); ``visible`` or none: in full.
    Rendered when the page is shown, so passing the deadline changes it without
    a regrade. The stored result keeps everything.
    """
    return result.with_tests(tuple(_cut(c, past_deadline) for c in result.tests))


def _cut(check: CheckResult, past_deadline: bool) -> CheckResult:
    level = check.level
    if level is None or level == "visible" or (level == "after_deadline" and past_deadline):
        return check
    if level == "input":
        shown = f"Input: {check.shown_input}" if check.shown_input else "The input is not described."
        return replace(check, output=shown if check.status != "passed" else "", attachments=())
    return replace(check, output=_LEVEL_NOTES[level] if check.status != "passed" else "",
                   attachments=())


def is_past(deadline: dt.datetime | None, now: dt.datetime | None = None) -> bool:
    """Whether ``deadline`` has passed (no deadline: never)."""
    if deadline is None:
        return False
    return (now or dt.datetime.now(dt.timezone.utc)) >= deadline


def _points(checks: list[CheckResult]) -> dict[str, str]:
    return {"score": f"{sum(c.score for c in checks):g}",
            "max_score": f"{sum(c.max_score for c in checks):g}"}


def render_feedback(folder: Path, result: SubmissionResult, *, title: str | None = None,
                    deadline: dt.datetime | None = None, now: dt.datetime | None = None) -> str:
    """The HTML of ``result``'s feedback page (pictures read from ``folder``), each check
    shown at its visibility level as of ``now`` and ``deadline``."""
    template = template_environment().get_template("feedback.html.j2")
    shown = as_students_see(result, past_deadline=is_past(deadline, now))
    return template.render(feedback_context(folder, shown, title=title))


def write_feedback(folder: Path, result: SubmissionResult, *, title: str | None = None,
                   deadline: dt.datetime | None = None) -> Path:
    """Write ``folder/feedback.html`` atomically; return its path.

    Parameters
    ----------
    folder : Path
        The submission's result folder (the one holding ``results.json``);
        attachment file names are relative to it.
    result : SubmissionResult
        Any outcome: an ungradable file or a grader error gets a page too.
    title : str, optional
        The assignment's title for the page heading (default: its name).
    """
    path = folder / FEEDBACK_NAME
    atomic_write_text(path, render_feedback(folder, result, title=title, deadline=deadline))
    return path


__all__ = ["FEEDBACK_NAME", "KIND_LABELS", "Picture", "as_students_see", "check_status", "is_past", "clean_text", "clip",
           "embed_picture", "feedback_context", "render_feedback", "template_environment",
           "write_feedback"]
