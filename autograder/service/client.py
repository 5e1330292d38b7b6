"""``autograder submit``: upload a notebook to a running service and wait for its score."""

from __future__ import annotations

import time
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
    """Upload ``notebook`` for ``assignment`` (default: the notebook's name) and wait for the grade."""
    import httpx

    notebook = Path(notebook)
    if not notebook.is_file():
        raise UsageError(f"{str(notebook)!r} is not a file; pass your .ipynb notebook.")
    if not token:
        raise UsageError("Pass your access token with --token (or set AUTOGRADER_TOKEN).")
    server = server.rstrip("/")
    name = assignment or notebook.stem
    headers = {"Authorization": f"Bearer {token}", "Accept": "application/json"}
    try:
        with httpx.Client(timeout=60.0, headers=headers) as client:
            with notebook.open("rb") as handle:
                answer = client.post(f"{server}/assignments/{name}/submissions",
                                     files={"notebook": (notebook.name, handle,
                                                         "application/x-ipynb+json")})
            if answer.status_code != 201:
                raise UsageError(_error(answer))
            view = _view(server, answer.json())
            deadline = time.monotonic() + wait
            while view.status in ("queued", "running") and time.monotonic() < deadline:
                time.sleep(poll)
                answer = client.get(f"{server}/api/submissions/{view.id}")
                if answer.status_code != 200:
                    raise UsageError(_error(answer))
                view = _view(server, answer.json())
            return view
    except httpx.HTTPError as exc:
        raise UsageError(f"Could not reach the grading service at {server}: {exc}.") from None


def _error(answer: Any) -> str:
    try:
        message = answer.json().get("error", "")
    except ValueError:
        message = answer.text[:300]
    return f"the service answered {answer.status_code}: {message}"


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
