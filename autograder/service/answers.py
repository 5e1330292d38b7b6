"""A student's written answer as staff read it: the cell found in their notebook, rendered safely.

Markdown is rendered on the server with mistune (the renderer nbconvert uses),
formulas with latex2mathml into MathML, which browsers draw natively: no script
and no CDN, so the grading page keeps its strict Content-Security-Policy. The
student wrote all of it, so everything that comes out goes through bleach (the
sanitiser nbconvert uses) with an allow-list of HTML and MathML elements and
attributes: a ``<script>`` smuggled through ``\\text{...}`` or a ``javascript:``
link through ``\\href`` is removed. Pictures are the cell outputs' PNG, JPEG and
GIF images, checked by their first bytes and shown as ``data:`` images.
"""

from __future__ import annotations

import base64
import binascii
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import bleach
import mistune
import nbformat
from latex2mathml.converter import convert as latex_to_mathml
from markupsafe import Markup, escape

#: where a numgrade notebook marks a manually graded cell: the tag ``manual:<question>``
TAG_PREFIX = "manual:"
MAX_PICTURES = 10
MAX_PICTURE_BYTES = 4 * 1024 * 1024
_MAGIC = {b"\x89PNG\r\n\x1a\n": "image/png", b"\xff\xd8\xff": "image/jpeg", b"GIF8": "image/gif"}
_MATHML = {"math", "mi", "mn", "mo", "ms", "mtext", "mrow", "mfrac", "msqrt", "mroot", "msub",
           "msup", "msubsup", "munder", "mover", "munderover", "mtable", "mtr", "mtd", "mspace",
           "mstyle", "mpadded", "mphantom", "menclose", "semantics", "annotation"}
_HTML = {"p", "br", "hr", "em", "strong", "code", "pre", "blockquote", "ul", "ol", "li", "a",
         "h1", "h2", "h3", "h4", "h5", "h6", "table", "thead", "tbody", "tr", "th", "td", "del",
         "div", "span"}
_ATTRIBUTES = {"a": ["href", "title"], "math": ["display"], "mo": ["stretchy", "fence"],
               "mfrac": ["linethickness"], "mtd": ["columnalign"], "mspace": ["width"],
               "mstyle": ["displaystyle", "scriptlevel"], "div": ["class"], "span": ["class"]}


@dataclass(frozen=True)
class Answer:
    """What a student wrote for one question: safe HTML, code (shown as text) and pictures."""

    found: bool
    html: Markup
    code: str
    pictures: tuple[str, ...]  # data: URIs


def _math(text: str, display: bool) -> str:
    try:
        mathml = latex_to_mathml(text, display="block" if display else "inline")
    except Exception:  # latex2mathml raises many kinds for malformed LaTeX: show it as written
        return f"<code>{escape(text)}</code>"
    return mathml


class _Renderer(mistune.HTMLRenderer):
    """mistune's HTML renderer with formulas as MathML (the math plugin's tokens)."""

    def block_math(self, text: str) -> str:
        return f"<div class=\"math\">{_math(text, True)}</div>\n"

    def inline_math(self, text: str) -> str:
        return _math(text, False)


_MARKDOWN = mistune.create_markdown(escape=True, renderer=_Renderer(escape=True),
                                    plugins=["math", "table", "strikethrough"])


def render_markdown(text: str) -> Markup:
    """Student-written markdown with formulas as safe HTML and MathML."""
    html = _MARKDOWN(text)
    assert isinstance(html, str)
    return Markup(bleach.clean(html, tags=_HTML | _MATHML, attributes=_ATTRIBUTES,
                               protocols=["http", "https", "mailto"], strip=True))


def _question_of(cell: Any) -> str | None:
    meta = cell.get("metadata", {})
    nbgrader = meta.get("nbgrader")
    if isinstance(nbgrader, dict) and isinstance(nbgrader.get("grade_id"), str):
        return nbgrader["grade_id"]
    tags = meta.get("tags")
    for tag in tags if isinstance(tags, list) else ():
        if isinstance(tag, str) and tag.startswith(TAG_PREFIX):
            return tag[len(TAG_PREFIX):]
    return None


def _picture(data: Any) -> str | None:
    if not isinstance(data, str) or len(data) > MAX_PICTURE_BYTES * 4 // 3 + 8:
        return None
    try:
        raw = base64.b64decode(data.replace("\n", ""), validate=True)
    except (binascii.Error, ValueError):
        return None
    media = next((m for magic, m in _MAGIC.items() if raw.startswith(magic)), None)
    return None if media is None else f"data:{media};base64,{base64.b64encode(raw).decode()}"


def _pictures(cell: Any) -> tuple[str, ...]:
    found = []
    for output in cell.get("outputs", []) if cell.get("cell_type") == "code" else []:
        data = output.get("data", {}) if isinstance(output, dict) else {}
        for media in ("image/png", "image/jpeg", "image/gif"):
            picture = _picture(data.get(media)) if isinstance(data, dict) else None
            if picture:
                found.append(picture)
    return tuple(found[:MAX_PICTURES])


def read_answer(notebook: Path, question: str) -> Answer:
    """The answer cell of ``question`` in the student's notebook (``found`` False if gone)."""
    try:
        book = nbformat.read(str(notebook), as_version=4)
    except Exception:  # the upload was accepted, so this is a damaged store; say so on the page
        return Answer(False, Markup(""), "", ())
    for cell in book.cells:
        if _question_of(cell) != question:
            continue
        source = cell.get("source", "")
        if cell.get("cell_type") == "markdown":
            return Answer(True, render_markdown(source), "", ())
        return Answer(True, Markup(""), source, _pictures(cell))
    return Answer(False, Markup(""), "", ())
