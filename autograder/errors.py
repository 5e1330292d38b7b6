"""Every exception the autograder raises, in one place.

Following scikit-learn's ``exceptions.py``: callers catch the family they care
about (``StudentError`` for what a submission did, ``UsageError`` for what the
person running the grader got wrong), and several classes also derive from a
built-in so that generic handlers keep working.
"""

from __future__ import annotations

__all__ = [
    "AutograderError",
    "UsageError",
    "AssignmentError",
    "UploadRejected",
    "NotebookError",
    "ProtocolError",
    "StudentError",
    "MissingFunction",
    "StudentException",
    "CallTimeout",
    "UnsupportedValue",
    "WorkerCrashed",
    "ProtocolViolation",
    "NotRun",
    "ForbiddenUse",
    "EngineError",
    "CheckFailure",
    "PartialCredit",
]


class AutograderError(Exception):
    """Base class of every error raised by the autograder."""


class UsageError(AutograderError, ValueError):
    """A wrong argument or setting; the message says which and how to fix it."""


class AssignmentError(UsageError):
    """An assignment folder is missing, incomplete or inconsistent."""


class UploadRejected(UsageError):
    """An upload the service refuses; ``status`` is the HTTP status to answer with."""

    def __init__(self, message: str, *, status: int = 400, retry_after: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.retry_after = retry_after


class NotebookError(AutograderError, ValueError):
    """A submitted file is not a gradable notebook (not JSON, invalid, wrong language)."""

    def __init__(self, message: str, *, kind: str = "invalid") -> None:
        super().__init__(message)
        #: short machine-readable reason: "not-json", "invalid", "too-large", "language", ...
        self.kind = kind


class ProtocolError(AutograderError):
    """A frame at the boundary was malformed, too large or too deep."""


class StudentError(AutograderError):
    """Something the student's code did (or did not do) made a call fail."""


class MissingFunction(StudentError, AttributeError):
    """The notebook does not define the function a check asked for."""


class StudentException(StudentError):
    """The student's function raised; ``traceback`` holds the student's traceback."""

    def __init__(self, message: str, *, traceback: str = "", function: str = "",
                 exc_type: str = "", detail: str = "") -> None:
        super().__init__(message)
        self.traceback = traceback
        #: what hidden checks may show: the function, the exception's type, its message
        self.function, self.exc_type, self.detail = function, exc_type, detail


class CallTimeout(StudentError, TimeoutError):
    """A call into the student's code did not return within its time limit."""


class UnsupportedValue(StudentError, TypeError):
    """A value returned by the student could not cross the boundary as plain data."""


class WorkerCrashed(StudentError):
    """The worker process died (killed by a limit, exited, or crashed)."""


class ProtocolViolation(WorkerCrashed):
    """The student's code wrote to the grader's connection: a frame the protocol does not
    expect there. The worker is stopped, as if it had crashed; never an engine error."""


class NotRun(StudentError):
    """A call was not made: the function ran out of time earlier on an input at least as large,
    or the submission used up its whole time budget."""


class EngineError(AutograderError):
    """The engine could not grade properly (worker set-up, incomplete sandbox, broken check run).

    Never a verdict on the student: the submission gets an ``error`` result, which is
    shown to the instructor and graded again on the next run.
    """


class ForbiddenUse(StudentError):
    """The student's code uses a name the assignment forbids (found by static analysis)."""


class CheckFailure(AssertionError):
    """A check's verdict with a message written for the student."""


class NoVariant(CheckFailure):
    """A check needs the student's variant and the student id has none (not on the roster):
    a person decides, the check is not scored zero."""


class PartialCredit(CheckFailure):
    """Ends a check as failed with ``fraction`` of its points and a message."""

    def __init__(self, fraction: float, message: str) -> None:
        super().__init__(message)
        self.fraction = fraction
