"""What the worker's answers mean on the trusted side: values, errors and frame names.

An answer to a call is plain data from an untrusted process. :func:`call_value`
turns it into the call's value or the student's error, every field cut to size;
:func:`answer_error` is shared by ordinary calls, batch items
(:mod:`autograder.engine.batch`) and the functions a student returned
(:mod:`autograder.engine.proxy`), so all meet the same caps. :func:`describe` and
:func:`shown` name what the child sent, for messages.
"""

from __future__ import annotations

from typing import Any

from autograder.boundary import values
from autograder.errors import (
    ForbiddenUse,
    MissingFunction,
    StudentException,
    UnsupportedValue,
    WorkerCrashed,
)

__all__ = ["answer_error", "call_value", "describe", "is_answer", "shown"]


def is_answer(message: Any) -> bool:
    """The answer to a request: a dict with "ok" and no "op" (see autograder.worker.loop)."""
    return isinstance(message, dict) and "op" not in message and "ok" in message


def shown(value: Any) -> str:
    """A value from the child, short enough for a message (a cell index counts from 1)."""
    if type(value) is int:
        return str(value + 1)
    return repr(value)[:40] if isinstance(value, (str, float)) else "?"


def describe(message: Any) -> str:
    """What kind of frame the child sent, for a message."""
    if isinstance(message, dict):
        op = message.get("op")
        return f"a {str(op)[:40]!r} frame" if isinstance(op, str) else "a frame without a known op"
    return f"a frame holding a {type(message).__name__}"


def answer_error(name: str, answer: dict[str, Any]) -> Exception:
    """The error a failed answer stands for, every field cut to size (the proxy uses it
    for the functions a student returned, so both kinds of call meet the same caps)."""
    error = answer.get("error")
    if error == "missing":
        return MissingFunction(
            f"Your notebook does not define `{name}`. Define a function with exactly this "
            "name at the top level of a code cell, and run every cell before submitting.")
    if error == "not-callable":
        return MissingFunction(
            f"`{name}` in your notebook is a {str(answer.get('type'))[:100]}, not a function.")
    if error == "exception" and answer.get("type") == "NotAllowedError":
        # Raised by the worker's guard when code reached a forbidden library at run time.
        return ForbiddenUse(f"{name} used a library this assignment does not allow: "
                            f"{str(answer.get('message', ''))[:500]}")
    if error == "exception":
        exc_type = str(answer.get("type", ""))[:100]
        detail = str(answer.get("message", ""))[:2000]
        return StudentException(f"{name} raised {exc_type}: {detail}",
                                traceback=str(answer.get("traceback", ""))[:20_000],
                                function=name, exc_type=exc_type, detail=detail)
    if error == "unsupported":
        return UnsupportedValue(
            f"{name} returned a value the grader cannot read ({str(answer.get('message'))[:300]}).")
    return WorkerCrashed(f"{name}: the worker answered {str(error)[:100]!r}.")


def call_value(name: str, answer: dict[str, Any]) -> Any:
    """The value an answer to a call of ``name`` holds, or raise the error it stands for."""
    if not answer.get("ok"):
        raise answer_error(name, answer)
    value = answer.get("value")
    if isinstance(value, values.Unsupported):
        raise UnsupportedValue(
            f"{name} returned a {value.type[:100]}, which the grader cannot read: return "
            "a number, a list or tuple of numbers, or a numpy array.")
    return value
