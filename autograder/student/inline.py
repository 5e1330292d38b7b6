"""``check()`` and ``submit()`` in a cell of the released notebook.

:func:`check` grades the notebook *as saved* with the public checks, through
:func:`autograder.api.check` (the same sandboxed worker as ``autograder check``), and
shows the result as an HTML table with the feedback's pictures in the cell's output.
:func:`submit` sends the saved notebook to the course's service with
:func:`autograder.service.client.submit` (standard library only).

Which notebook: the ``notebook=`` argument; else the one Jupyter names for this
kernel (``__session__`` in the kernel's namespace, or ``$JPY_SESSION_NAME``, set by
jupyter-server 2 and JupyterLab); else, in the kernel's working folder (the
notebook's folder, where Jupyter starts kernels), the notebook the release's
``assignment.toml`` names.
"""

from __future__ import annotations

import datetime as dt
import html
import os
import re
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autograder.errors import UsageError
from autograder.results.feedback import KIND_LABELS, check_status, clean_text, embed_picture
from autograder.results.model import SubmissionResult

#: the notebook metadata key the course's service address is read from
SERVER_METADATA = ("numgrade", "server")


@dataclass(frozen=True)
class CheckReport:
    """What :func:`check` shows: the result, the checks shown, and the table as HTML.

    Jupyter displays it through ``_repr_html_``; ``str()`` gives plain text.
    """

    result: SubmissionResult
    notebook: Path
    function: str | None
    html: str
    text: str

    def _repr_html_(self) -> str:
        return self.html

    def __str__(self) -> str:
        return self.text

    @property
    def score(self) -> float:
        return sum(t.score for t in self.shown)

    @property
    def max_score(self) -> float:
        return sum(t.max_score for t in self.shown)

    @property
    def shown(self) -> tuple[Any, ...]:
        return tuple(t for t in self.result.tests if not t.hidden
                     and (self.function is None or _is_of(t.name, self.function)))


def _kernel_namespace() -> dict[str, Any]:
    try:
        from IPython import get_ipython
    except ImportError:
        return {}
    shell = get_ipython()
    return dict(getattr(shell, "user_ns", {}) or {})


def find_notebook(notebook: str | Path | None = None, *, folder: Path | None = None) -> Path:
    """The notebook to check or submit (see the module's docstring for the order)."""
    if notebook is not None:
        path = Path(notebook)
        if not path.is_file():
            raise UsageError(f"{str(path)!r} is not a file; pass the path of your .ipynb notebook.")
        return path.resolve()
    for named in (_kernel_namespace().get("__session__"), os.environ.get("JPY_SESSION_NAME")):
        if isinstance(named, str) and named.endswith(".ipynb") and Path(named).is_file():
            return Path(named).resolve()
    folder = Path(folder or Path.cwd())
    name = _released(folder, "notebook")
    if name and (folder / name).is_file():
        return (folder / name).resolve()
    raise UsageError(
        f"Cannot tell which notebook this is: {str(folder)!r} holds no released assignment.toml "
        "naming a notebook that exists. Open the notebook from the folder you were given, or "
        "pass it: check(notebook='hull.ipynb').")


def _released(folder: Path, key: str) -> str | None:
    """``[assignment] key`` of the release's ``assignment.toml`` in ``folder`` (None if absent)."""
    try:
        table = tomllib.loads((folder / "assignment.toml").read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError):
        return None
    section = table.get("assignment")
    value = section.get(key) if isinstance(section, dict) else None
    return value if isinstance(value, str) else None


def _is_of(check_name: str, function: str) -> bool:
    """True when ``check_name`` (``test_convex_hull_small[square]``) checks ``function``."""
    base = check_name.split("[", 1)[0]
    return re.search(rf"(?:^|_){re.escape(function)}(?:_|$)", base) is not None


def check(function: str | None = None, *, notebook: str | Path | None = None) -> CheckReport:
    """Run the public checks on this notebook as saved; show the table in the cell's output.

    ``function``: show only the checks of that function (``check("convex_hull")``).
    Save the notebook first (Ctrl+S): what is checked is the file, as the grader sees it.
    """
    from autograder import api

    path = find_notebook(notebook)
    folder = path.parent
    assignment = folder if (folder / "assignment.toml").is_file() else None
    with tempfile.TemporaryDirectory(prefix="numgrade-check-") as scratch:
        result = api.check(path, assignment=assignment, out_dir=Path(scratch) / "result")
        if function is not None and not any(_is_of(t.name, function) for t in result.tests
                                            if not t.hidden):
            names = sorted({t.name.split("[", 1)[0] for t in result.tests if not t.hidden})
            raise UsageError(f"No public check is about {function!r}; the checks are "
                             f"{', '.join(names) or 'none'}. Call check() for all of them.")
        shown = [t for t in result.tests if not t.hidden and (function is None
                                                              or _is_of(t.name, function))]
        page = _table(Path(scratch) / "result", result, shown, path)
    saved = dt.datetime.fromtimestamp(path.stat().st_mtime).strftime("%H:%M:%S")
    text = "\n".join([f"{path.name} as saved at {saved}: {result.output}",
                      *(f"  {'PASS' if t.status == 'passed' else 'FAIL'}  {t.name}  "
                        f"{t.score:g}/{t.max_score:g}" for t in shown)])
    return CheckReport(result, path, function, page, text)


def _table(folder: Path, result: SubmissionResult, shown: list[Any], path: Path) -> str:
    """The cell's HTML: a caption, one row per check (pictures inline), the cell errors.
    Every text comes from the student's run and is escaped."""
    saved = dt.datetime.fromtimestamp(path.stat().st_mtime).strftime("%H:%M:%S")
    rows = []
    for test in shown:
        status = check_status(test)
        label = "passed" if status == "passed" else KIND_LABELS.get(test.kind, test.kind)
        pictures = "".join(
            f'<figure><img src="{p.uri}" alt="{html.escape(p.label)}" style="max-width:28em">'
            f"<figcaption>{html.escape(p.label)}</figcaption></figure>" if p.uri else
            f"<p>{html.escape(p.label)}: {html.escape(p.problem)}</p>"
            for p in (embed_picture(folder, a) for a in test.attachments))
        rows.append(f'<tr class="numgrade-{status}"><td><code>{html.escape(test.name)}</code></td>'
                    f"<td>{html.escape(label)}</td><td>{test.score:g}/{test.max_score:g}</td>"
                    f"<td><pre>{html.escape(clean_text(test.output))}</pre>{pictures}</td></tr>")
    errors = "".join(f"<li>cell {e.cell + 1} raised {html.escape(e.ename)}: "
                     f"{html.escape(clean_text(e.evalue)[:300])}</li>" for e in result.cell_errors)
    score = sum(t.score for t in shown)
    top = sum(t.max_score for t in shown)
    return ('<table class="numgrade-check"><caption>'
            f"Public checks of {html.escape(path.name)} as saved at {saved}: {score:g}/{top:g} "
            "points. Hidden checks run when your notebook is graded.</caption>"
            "<thead><tr><th>check</th><th>result</th><th>points</th><th>details</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>"
            + (f"<ul>{errors}</ul>" if errors else ""))


def submit(*, notebook: str | Path | None = None, server: str | None = None,
           token: str | None = None, wait: float = 600.0) -> Any:
    """Send this notebook as saved to the course's service; show the score when it is graded.

    ``server``: default ``$AUTOGRADER_SERVER``, else the address the release wrote in the
    notebook's metadata (``numgrade.server``). ``token``: default ``$AUTOGRADER_TOKEN``.
    """
    from autograder.service.client import describe, submit as upload

    path = find_notebook(notebook)
    address = server or os.environ.get("AUTOGRADER_SERVER") or _metadata_server(path)
    if not address:
        raise UsageError("This release does not say where the course's service is: pass "
                         "submit(server='https://...') or set AUTOGRADER_SERVER.")
    name = _released(path.parent, "name") or path.stem
    result = upload(path, server=address, token=token or os.environ.get("AUTOGRADER_TOKEN", ""),
                    assignment=name, wait=wait)
    print(describe(result))
    return result


def _metadata_server(path: Path) -> str | None:
    import json

    try:
        value: Any = json.loads(path.read_text(encoding="utf-8")).get("metadata", {})
    except (OSError, ValueError, AttributeError):
        return None
    for key in SERVER_METADATA:
        value = value.get(key) if isinstance(value, dict) else None
    return value if isinstance(value, str) and value.startswith(("http://", "https://")) else None
