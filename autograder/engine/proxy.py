"""The ``student`` object that checks call: every attribute is a function across the boundary.

``student.convex_hull(points)`` sends the call to the sandboxed worker with a
time limit and returns the value rebuilt as plain data on this side.

Functions cross both ways without their code: a callable a check passes (at
any depth of lists, tuples and dicts) is registered in a
:class:`~autograder.engine.callbacks.CallbackRegistry` for that call and evaluated
here when the student's code calls it; a function the student returns comes
back as a :class:`StudentFunction`, which calls into the worker when called,
with the same time limit, and dies with the submission.

Both directions meet the same bounds as an ordinary call: a returned function's
errors are built by :func:`~autograder.engine.answers.answer_error` (the
same caps, and the fields hidden checks use to show only a short excerpt), and
figures, in answers or inside returned values, are validated and cut to the
figure budget here (:mod:`autograder.engine.figuredata`), whatever the worker sent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Iterable, Iterator, Sequence
from typing import Any, Callable, Protocol

from autograder.boundary import values
from autograder.engine.batch import Outcome
from autograder.engine.callbacks import CallbackRegistry, holds_callable, limit_message
from autograder.engine.figuredata import receive_figures, receive_value
from autograder.engine.answers import answer_error
from autograder.errors import (
    ForbiddenUse,
    MissingFunction,
    StudentError,
    StudentException,
    UnsupportedValue,
    UsageError,
    WorkerCrashed,
)

__all__ = ["CallLog", "CallTarget", "Student", "StudentFunction"]


class CallTarget(Protocol):
    """What the proxy needs from a session (a real worker or an unreadable notebook).

    A session that can answer callbacks also has an ``on_callback`` attribute and a
    ``request(message, *, timeout, what)`` method (see :mod:`autograder.engine.student_process`).
    """

    def call(self, name: str, args: Any, kwargs: dict[str, Any], *, timeout: float,
             figures: bool = False) -> tuple[Any, list[Any]]: ...

    def figures(self, *, timeout: float) -> list[Any]: ...


@dataclass
class CallLog:
    """Which student functions the current check called (for the forbidden-name rule)."""

    names: list[str] = field(default_factory=list)
    #: a call into the worker is running (a check's function, answering a callback,
    #: must not call the student's code: the worker is waiting for its answer)
    busy: bool = False
    #: for the instructor's log: exceptions the check's functions raised on the
    #: student's arguments (each was raised in the student's code as the student's error)
    notes: list[str] = field(default_factory=list)


class Student:
    """Proxy for the submitted notebook's top-level functions."""

    def __init__(self, target: CallTarget, *, timeout: float, functions: tuple[str, ...],
                 forbidden: dict[str, str], log: CallLog) -> None:
        self._target = target
        self._timeout = timeout
        self._functions = functions
        self._forbidden = forbidden
        self._log = log

    def __getattr__(self, name: str) -> Callable[..., Any]:
        if name.startswith("_"):
            raise AttributeError(name)

        def call(*args: Any, **kwargs: Any) -> Any:
            value, _ = self.call(name, *args, **kwargs)
            return value

        call.__name__ = name
        return call

    def has(self, name: str) -> bool:
        """Whether the notebook defined a callable called ``name``."""
        return name in self._functions

    def call(self, name: str, *args: Any, timeout: float | None = None,
             figures: bool = False, **kwargs: Any) -> tuple[Any, list[Any]]:
        """Call ``name``; return ``(value, figures created during the call)``."""
        self._log.names.append(name)
        if name in self._forbidden:
            raise ForbiddenUse(self._forbidden[name])
        if self._functions and name not in self._functions:
            # Saves a round trip; the worker would say the same.
            raise MissingFunction(
                f"Your notebook does not define `{name}`. Define a function with exactly "
                "this name at the top level of a code cell.")
        limit = timeout or self._timeout

        def send(a: list[Any], k: dict[str, Any]) -> tuple[Any, list[Any]]:
            return self._target.call(name, a, k, timeout=limit, figures=figures)

        return self._invoke(send, args, kwargs, what=f"{name}()")

    def map(self, name: str, items: Iterable[Sequence[Any]], *,
            timeout: float | None = None) -> Iterator[Any]:
        """Call ``name(*args)`` for each ``args`` in ``items``: an iterator of the values.

        Like ``itertools.starmap``: each item is the tuple (or list) of one call's
        positional arguments. The calls cross the boundary as one batch
        (:mod:`autograder.engine.batch`), which costs far less than one crossing per
        call, and each is still a call of its own: its own time limit, and at its
        position the iterator raises the error that call raised (the iterator goes
        on after it). A check may stop reading at any point. Items holding
        functions are called one by one, as :meth:`call` would.
        """
        calls = [_arguments(name, item) for item in items]
        if self._log.busy:
            raise UsageError(
                f"student.map({name!r}, ...) was called from inside a function given to "
                "student code; call it before or after.")
        self._log.names.append(name)
        limit = timeout or self._timeout
        many = getattr(self._target, "call_many", None)
        if (name in self._forbidden or (self._functions and name not in self._functions)
                or many is None or any(holds_callable(args) for args in calls)):
            return _Results(self, name, self._one_by_one(name, calls, limit), received=True)
        return _Results(self, name, many(name, calls, timeout=limit))

    def _one_by_one(self, name: str, calls: list[list[Any]], limit: float) -> Iterator[Outcome]:
        for args in calls:
            try:
                value, _ = self.call(name, *args, timeout=limit)
            except StudentError as exc:
                yield Outcome(error=exc)
            else:
                yield Outcome(value=value)

    def figures(self) -> list[Any]:
        """Data of the figures the notebook left open (one dict per figure)."""
        return receive_figures(self._target.figures(timeout=self._timeout))

    # -- functions across the boundary ------------------------------------------
    def _invoke(self, send: Callable[[list[Any], dict[str, Any]], tuple[Any, list[Any]]],
                args: tuple[Any, ...], kwargs: dict[str, Any], *,
                what: str) -> tuple[Any, list[Any]]:
        """Send one call with the check's functions registered for callbacks."""
        if self._log.busy:
            raise UsageError(
                f"{what} was called from inside a function given to student code; a check's "
                "function runs while the student's call waits for it and cannot call the "
                "student's code. Call it before or after.")
        registry = CallbackRegistry(own_ref=self._own_ref, notes=self._log.notes)
        plain_args = registry.export(list(args))
        plain_kwargs = registry.export(dict(kwargs))
        answers = hasattr(self._target, "on_callback")
        previous = getattr(self._target, "on_callback", None)
        if answers:
            self._target.on_callback = registry.answer  # type: ignore[attr-defined]
        self._log.busy = True
        try:
            value, figures = send(plain_args, plain_kwargs)
        except StudentError:
            if registry.check_error is not None:  # the student's code only saw its effect
                raise registry.check_error from None
            raise
        finally:
            self._log.busy = False
            if answers:
                self._target.on_callback = previous  # type: ignore[attr-defined]
        if registry.check_error is not None:
            raise registry.check_error
        if registry.exceeded:
            name = next(iter(registry.functions.values())).name
            raise StudentException(f"{what}: " + limit_message(name, registry.max_callbacks))
        returned = f"the function returned by {what}"
        value = values.replace_refs(value, lambda ref: StudentFunction(self, ref, returned))
        return receive_value(value), receive_figures(figures)

    def _own_ref(self, value: object) -> values.CallableRef | None:
        if isinstance(value, StudentFunction) and value._student is self:
            return value._ref
        return None

    def _call_ref(self, ref: values.CallableRef, args: list[Any], kwargs: dict[str, Any],
                  what: str) -> tuple[Any, list[Any]]:
        request = getattr(self._target, "request", None)
        if request is None:
            raise WorkerCrashed(f"{what} cannot be called: the notebook is not running.")
        answer = request({"op": "call-ref", "id": ref.id, "args": args, "kwargs": kwargs},
                         timeout=self._timeout, what=what)
        if not answer.get("ok"):
            if answer.get("error") == "stale-ref":
                raise WorkerCrashed(f"{what} is gone: your notebook's worker was restarted "
                                    "after an earlier call stopped it.")
            # the same error, caps and hidden-check excerpt as a call of a top-level function
            raise answer_error(what, answer)
        value = answer.get("value")
        if isinstance(value, values.Unsupported):
            raise UnsupportedValue(f"{what} returned a {value.type[:100]}, which the grader cannot "
                                   "read: return a number, a list or tuple of numbers, or a "
                                   "numpy array.")
        return value, []


class StudentFunction:
    """A function the student's code returned; calling it runs it in the worker.

    Each call has the same time limit as a call of a top-level function, and
    raises the same errors (:class:`~autograder.errors.StudentException` when the
    student's code raised, and so on). It works while the submission's worker
    runs, that is, during the checks of this submission.
    """

    def __init__(self, student: Student, ref: values.CallableRef, what: str) -> None:
        self._student = student
        self._ref = ref
        #: how messages name it: "the function returned by make_interpolant()"
        self.what = what

    def __repr__(self) -> str:
        return f"<{self.what}>"

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        def send(a: list[Any], k: dict[str, Any]) -> tuple[Any, list[Any]]:
            return self._student._call_ref(self._ref, a, k, self.what)

        value, _ = self._student._invoke(send, args, kwargs, what=self.what)
        return value


def _arguments(name: str, item: Any) -> list[Any]:
    """One call's positional arguments from an item of ``student.map``."""
    if not isinstance(item, (tuple, list)):
        raise UsageError(
            f"student.map({name!r}, items): each item is the tuple of one call's arguments, "
            f"like itertools.starmap, not a {type(item).__name__}; write [(x,) for x in xs] "
            "for a function of one argument.")
    return list(item)


class _Results:
    """The values of a batch, in order; an item's error is raised at its position and the
    iteration goes on after it (a generator would end at the first error)."""

    def __init__(self, student: Student, name: str, outcomes: Iterator[Outcome], *,
                 received: bool = False) -> None:
        self._student = student
        self._what = f"{name}()"
        self._outcomes = outcomes
        #: the values are already as :meth:`Student.call` returns them
        self._received = received

    def __iter__(self) -> _Results:
        return self

    def __next__(self) -> Any:
        outcome = next(self._outcomes)
        if outcome.error is not None:
            raise outcome.error
        if self._received:
            return outcome.value
        returned = f"the function returned by {self._what}"
        value = values.replace_refs(
            outcome.value, lambda ref: StudentFunction(self._student, ref, returned))
        return receive_value(value)
