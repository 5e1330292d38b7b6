"""Answer the grader's requests inside the sandboxed child.

Requests and answers are plain data (see :mod:`autograder.protocol`). The child
never learns what a check expects: it only runs the function it is asked to run
and sends back what came out.
"""

from __future__ import annotations

import socket
import traceback
from typing import Any

from autograder import protocol
from autograder.worker import figures
from autograder.worker.execute import BoundedText, GradingShell

#: frames from these files are the worker's own plumbing, not the student's code
_OWN_FILES = ("autograder/worker/", "autograder/protocol.py")


def student_traceback(exc: BaseException) -> str:
    """The traceback of ``exc`` without the worker's own frames."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__)
              if not any(own in f.filename.replace("\\", "/") for own in _OWN_FILES)]
    lines = ["Traceback (most recent call last):\n"]
    lines += traceback.format_list(frames)
    lines += traceback.format_exception_only(type(exc), exc)
    return "".join(lines)[-20_000:]


def defined_functions(shell: GradingShell) -> list[str]:
    """Names of the callables the notebook defined at top level."""
    hidden = set(shell.user_ns_hidden)
    return sorted(name for name, value in list(shell.user_ns.items())
                  if not name.startswith("_") and name not in hidden and callable(value))


def _call(shell: GradingShell, request: dict[str, Any]) -> dict[str, Any]:
    name = request.get("name")
    target = shell.user_ns.get(name) if isinstance(name, str) else None
    if target is None or not callable(target):
        kind = "missing" if target is None else "not-callable"
        return {"ok": False, "error": kind, "type": type(target).__name__}
    before = set(figures.open_figure_numbers())
    try:
        value = target(*request.get("args", ()), **request.get("kwargs", {}))
    except BaseException as exc:  # anything the student's code raises, SystemExit included
        return {"ok": False, "error": "exception", "type": type(exc).__name__,
                "message": _message(exc), "traceback": student_traceback(exc)}
    answer: dict[str, Any] = {"ok": True, "value": value}
    if request.get("figures"):
        answer["figures"] = figures.figures_data(exclude=before)
    return answer


def _message(exc: BaseException) -> str:
    try:
        return str(exc)[:2000]
    except BaseException:  # hostile __str__
        return "<unprintable exception>"


def handle(shell: GradingShell, output: BoundedText, request: dict[str, Any]) -> dict[str, Any]:
    """Answer one request; never raises for anything the student's code does."""
    op = request.get("op")
    if op == "call":
        answer = _call(shell, request)
    elif op == "figures":
        answer = {"ok": True, "value": figures.figures_data()}
    elif op == "functions":
        answer = {"ok": True, "value": defined_functions(shell)}
    else:
        answer = {"ok": False, "error": "bad-request", "message": f"unknown op {op!r}"}
    answer["stdout"] = output.take()
    return answer


def serve(sock: socket.socket, shell: GradingShell, output: BoundedText) -> None:
    """Answer requests until the grader says goodbye or goes away."""
    while True:
        try:
            request = protocol.recv_message(sock)
        except (EOFError, OSError, protocol.ProtocolError):
            return
        if not isinstance(request, dict) or request.get("op") == "bye":
            return
        answer = handle(shell, output, request)
        send_answer(sock, answer)


def send_answer(sock: socket.socket, answer: dict[str, Any]) -> None:
    """Send ``answer``; a value that cannot be framed becomes an 'unsupported' answer."""
    try:
        protocol.send_message(sock, answer, figure_encoder=figures.figure_to_data)
    except protocol.ProtocolError as exc:
        protocol.send_message(sock, {"ok": False, "error": "unsupported",
                                     "message": str(exc), "stdout": ""})
