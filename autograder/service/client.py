"""``autograder submit``: upload a notebook to a running service and wait for its score."""

from __future__ import annotations

import json
import secrets
import time
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autograder.errors import UsageError


@dataclass(frozen=True)
class Submitted:
    """What the service said about an upload."""

    id: int
    status: str
    score: float | None
    max_score: float | None
    late_days: int
    feedback_url: str | None
    url: str
    message: str


def _view(server: str, data: dict[str, Any]) -> Submitted:
    feedback = data.get("feedback_url")
    return Submitted(id=int(data["id"]), status=str(data["status"]), score=data.get("score"),
                     max_score=data.get("max_score"), late_days=int(data.get("late_days", 0)),
                     feedback_url=server + feedback if feedback else None,
                     url=server + str(data["url"]), message=str(data.get("message", "")))


def submit(notebook: Path, *, server: str, token: str, assignment: str | None = None,
           wait: float = 600.0, poll: float = 0.5) -> Submitted:
    """Upload ``notebook`` for ``assignment`` (default: the notebook's name) and wait for the grade.

    Only the standard library (:mod:`urllib`): this is what a student's install runs,
    which holds none of the service's stack.
    """
    notebook = Path(notebook)
    if not notebook.is_file():
        raise UsageError(f"{str(notebook)!r} is not a file; pass your .ipynb notebook.")
    if not token:
        raise UsageError("Pass your access token with --token (or set AUTOGRADER_TOKEN).")
    server = server.rstrip("/")
    if not server.startswith(("http://", "https://")):
        raise UsageError(f"--server {server!r}: give the service's address with http:// or "
                         "https://, e.g. https://grader.example.edu.")
    name = assignment or notebook.stem
    headers = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    body, content_type = _form_file("notebook", notebook.name, notebook.read_bytes())
    status, data = _call(urllib.request.Request(
        f"{server}/assignments/{urllib.parse.quote(name, safe='')}/submissions", data=body,
        method="POST", headers={**headers, "Content-Type": content_type}), server)
    if status != 201:
        raise UsageError(_error(status, data))
    view = _view(server, data)
    deadline = time.monotonic() + wait
    while view.status in ("queued", "running") and (left := deadline - time.monotonic()) > 0:
        # The service answers once the attempt is graded, or after ``wait`` seconds; a
        # service older than that answers at once, and is then asked every ``poll`` s.
        asked = time.monotonic()
        status, data = _call(urllib.request.Request(
            f"{server}/api/submissions/{view.id}?wait={min(LONG_POLL, left):.1f}",
            headers=headers), server)
        if status != 200:
            raise UsageError(_error(status, data))
        view = _view(server, data)
        if view.status in ("queued", "running") and time.monotonic() - asked < poll:
            time.sleep(poll)
    return view


#: seconds one status request may wait for the grade (the service's limit is 60)
LONG_POLL = 20.0


def _form_file(field: str, filename: str, content: bytes) -> tuple[bytes, str]:
    """A multipart/form-data body with one file (RFC 7578). Written here because the
    standard library has no encoder for it (``email`` writes MIME mail, not form data)."""
    boundary = f"numgrade-{secrets.token_hex(16)}"
    quoted = filename.replace("\\", "_").replace('"', "_").replace("\r", "_").replace("\n", "_")
    head = (f"--{boundary}\r\nContent-Disposition: form-data; name=\"{field}\"; "
            f"filename=\"{quoted}\"\r\nContent-Type: application/x-ipynb+json\r\n\r\n")
    return (head.encode("utf-8") + content + f"\r\n--{boundary}--\r\n".encode(),
            f"multipart/form-data; boundary={boundary}")


def _call(request: urllib.request.Request, server: str) -> tuple[int, Any]:
    """(status, the JSON answer or its text); any status, never an exception for 4xx/5xx."""
    try:
        with urllib.request.urlopen(request, timeout=60.0) as answer:
            status, raw = answer.status, answer.read()
    except urllib.error.HTTPError as exc:
        status, raw = exc.code, exc.read()
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        raise UsageError(f"Could not reach the grading service at {server}: {reason}.") from None
    try:
        return status, json.loads(raw)
    except ValueError:
        return status, raw.decode("utf-8", "replace")


def _error(status: int, data: Any) -> str:
    message = data.get("error", "") if isinstance(data, dict) else str(data)[:300]
    return f"the service answered {status}: {message}"


def describe(result: Submitted) -> str:
    """The lines ``autograder submit`` prints."""
    lines = [f"Attempt {result.id}: {result.status}"]
    if result.score is not None:
        late = f" ({result.late_days} day(s) late, penalty applied)" if result.late_days else ""
        lines.append(f"Score: {result.score:g}/{result.max_score:g}{late}")
    if result.message:
        lines.append(result.message)
    if result.feedback_url:
        lines.append(f"Feedback: {result.feedback_url}")
    elif result.status in ("queued", "running"):
        lines.append(f"Still being graded; follow it at {result.url}")
    return "\n".join(lines)
