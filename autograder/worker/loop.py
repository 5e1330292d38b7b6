"""Answer the grader's requests inside the sandboxed child.

Requests and answers are plain data (see :mod:`autograder.boundary.codec`). The child
never learns what a check expects: it only runs the function it is asked to run
and sends back what came out.

Functions across the boundary
-----------------------------
A function a check passes arrives as a :class:`~autograder.boundary.values.CallableRef`
and is handed to the student as a :class:`GraderFunction` stub. Calling the
stub sends ``{"op": "callback", "id", "args", "kwargs"}`` to the grader, which
runs the real function on its side and answers ``{"op": "callback-result",
...}``; the function's code never enters this process. A ref with a ``safe``
name (a pure numpy ufunc from :data:`~autograder.boundary.values.SAFE_FUNCTIONS`) is
evaluated here instead, and its calls are counted and reported to the grader
(``{"op": "callback", "tally": [...]}``, not answered) before the call's answer. A stub is
valid for the one call it was passed to: used after that call returned, it
raises :class:`StaleCallback`.

A function the student *returns* is kept in a table here and crosses as a
ref; the grader calls it with ``{"op": "call-ref", "id", "args", "kwargs"}``.

Batches
-------
``{"op": "map", "batch", "name", "items"}`` asks for many calls of one function
(:func:`serve_map`): each is answered in a frame of its own, tagged with the batch
and the call's position, and ``map-done`` follows the last.

Forked children
---------------
Only the process that serves owns the socket (:func:`protect_channel`): a child the
student's code forks has it closed at once, and a child that unwinds back into
:func:`serve` (say, after a refused ``setsid()``) exits there without reading or
answering, so a parent's verdicts are never answered by its children.
"""

from __future__ import annotations

import os
import socket
import traceback
from typing import Any, Callable

import numpy as np

from autograder.boundary import codec, frames, values
from autograder.errors import ProtocolError
from autograder.worker import figures
from autograder.worker.execute import BoundedText, GradingShell

#: frames from these files are the worker's own plumbing, not the student's code
_OWN_FILES = ("autograder/worker/", "autograder/boundary/codec.py", "autograder/boundary/frames.py")
#: most functions the student may return over one submission (each is kept until the end)
MAX_RETURNED_FUNCTIONS = 10_000
#: most evaluation points recorded per safe function and call (calls are always counted)
MAX_RECORDED_POINTS = 1_000_000
#: exception types a grader-side function's failure is raised as in the student's code
_BUILTIN_ERRORS: dict[str, type[Exception]] = {
    cls.__name__: cls for cls in (TypeError, ValueError, ZeroDivisionError, OverflowError,
                                  ArithmeticError, FloatingPointError, IndexError, KeyError,
                                  RuntimeError)}


class StaleCallback(RuntimeError):
    """A function the grader passed was called after the call it was passed to returned."""


class CallbackLimitExceeded(BaseException):
    """The student's code called the grader's functions more often than one call allows.

    A ``BaseException``, like ``KeyboardInterrupt``: ``except Exception`` in the
    student's loop does not swallow it, and once raised, every further call of a
    grader function in the same call raises it again at once, without asking the
    grader, so a loop that swallows it anyway only burns its own CPU time.
    """


def student_traceback(exc: BaseException) -> str:
    """The traceback of ``exc`` without the worker's own frames."""
    shown = [f for f in traceback.extract_tb(exc.__traceback__)
             if not any(own in f.filename.replace("\\", "/") for own in _OWN_FILES)]
    lines = ["Traceback (most recent call last):\n"]
    lines += traceback.format_list(shown)
    lines += traceback.format_exception_only(type(exc), exc)
    return "".join(lines)[-20_000:]


def defined_functions(shell: GradingShell) -> list[str]:
    """Names of the callables the notebook defined at top level."""
    hidden = set(shell.user_ns_hidden)
    return sorted(name for name, value in list(shell.user_ns.items())
                  if not name.startswith("_") and name not in hidden and callable(value))


class GraderFunction:
    """What student code gets for a function a check passed: calling it asks the grader."""

    __slots__ = ("_channel", "_ref", "_generation", "_local", "_calls", "_points", "_recorded")

    def __init__(self, channel: "Channel", ref: values.CallableRef) -> None:
        self._channel = channel
        self._ref = ref
        self._generation = channel.generation
        self._local: Callable[..., Any] | None = _safe_function(ref.safe)
        self._calls = 0
        self._points: list[np.ndarray] = []
        self._recorded = 0

    @property
    def __name__(self) -> str:  # noqa: A003 - read by tracebacks and student code
        return self._ref.name

    def __repr__(self) -> str:
        return f"<function {self._ref.name} given by the grader>"

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        channel = self._channel
        if self._generation != channel.generation or not channel.in_call:
            raise StaleCallback(
                f"`{self._ref.name}` was given to your function for one call only, and that "
                "call has returned; do not keep it (in a global, a default argument or a "
                "closure) to call it later. Sample what you need before returning.")
        if self._local is None:
            return channel.callback(self._ref, args, kwargs)
        self._calls += 1
        if self._calls == 1:
            channel.used_locally.append(self)
        if args and self._recorded < MAX_RECORDED_POINTS:
            try:
                point = np.array(args[0], dtype=float).reshape(-1)
            except (TypeError, ValueError):
                point = None
            if point is not None:
                self._points.append(point[: MAX_RECORDED_POINTS - self._recorded])
                self._recorded += point.size
        return self._local(*args, **kwargs)

    def _tally(self) -> dict[str, Any]:
        points = np.concatenate(self._points) if self._points else np.zeros(0)
        return {"id": self._ref.id, "calls": self._calls, "points": points,
                "truncated": self._recorded >= MAX_RECORDED_POINTS}


def _safe_function(name: str) -> Callable[..., Any] | None:
    """The numpy function a safe name stands for (names are checked when decoded)."""
    if not name or name not in values.SAFE_FUNCTIONS:
        return None
    function = getattr(np, name.split(".", 1)[1], None)
    return function if isinstance(function, np.ufunc) else None


class Channel:
    """The socket to the grader, the current call's generation and the returned functions."""

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.generation = 0
        self.in_call = False
        #: the grader's message once it refused more callbacks in this call
        self.limited = ""
        self.used_locally: list[GraderFunction] = []
        self.returned: dict[str, Callable[..., Any]] = {}
        self._next = 0

    # -- functions given by the grader ------------------------------------------
    def stubs(self, value: Any) -> Any:
        """``value`` with each ref replaced by a stub bound to the coming call (or by the
        student's own function, for a ref the student returned earlier)."""
        return values.replace_refs(value, self._resolve)

    def _resolve(self, ref: values.CallableRef) -> Any:
        own = self.returned.get(ref.id)
        return GraderFunction(self, ref) if own is None else own

    def callback(self, ref: values.CallableRef, args: tuple, kwargs: dict[str, Any]) -> Any:
        """Ask the grader to evaluate ``ref``; return its value or raise its error here."""
        if self.limited:
            raise CallbackLimitExceeded(self.limited)
        message = {"op": "callback", "id": ref.id, "args": list(args), "kwargs": kwargs}
        try:
            tree, buffers = codec.encode(message)
        except ProtocolError as exc:
            raise TypeError(f"the arguments passed to `{ref.name}` cannot be sent: {exc}; "
                            "pass numbers or numpy arrays of numbers") from None
        reply = self._exchange(tree, buffers)
        if not isinstance(reply, dict):
            raise RuntimeError(f"the grader sent no answer for `{ref.name}`")
        if reply.get("ok"):
            value = reply.get("value")
            if isinstance(value, values.Unsupported):
                raise TypeError(f"`{ref.name}` gave a value that cannot be sent to your code")
            return value
        error, message_text = str(reply.get("error", "")), str(reply.get("message", ""))[:2000]
        if error == "limit":
            self.limited = message_text or "too many calls of the grader's functions"
            raise CallbackLimitExceeded(self.limited)
        if error == "stale":
            raise StaleCallback(message_text)
        raise _BUILTIN_ERRORS.get(str(reply.get("type")), RuntimeError)(message_text)

    def _exchange(self, tree: Any, buffers: list[Any]) -> Any:
        leave_if_forked()
        try:
            frames.send_frame(self.sock, tree, buffers)
            return frames.recv_message(self.sock)
        except (EOFError, OSError, ProtocolError):
            os._exit(0)  # the grader is gone or out of step: nothing is left to do here

    def end_call(self) -> None:
        """Report the safe functions' counts, then make every stub of this call stale."""
        used, self.used_locally = self.used_locally, []
        self.in_call, self.limited = False, ""
        self.generation += 1
        if used:
            leave_if_forked()
            # Not answered by the grader: this saves a round trip per call.
            tree, buffers = codec.encode({"op": "callback",
                                             "tally": [stub._tally() for stub in used]})
            try:
                frames.send_frame(self.sock, tree, buffers)
            except (OSError, ProtocolError):
                os._exit(0)

    # -- functions the student returns ------------------------------------------
    def export(self, value: object) -> values.CallableRef | None:
        """A ref for a function the student returns (``None`` once the table is full)."""
        if len(self.returned) >= MAX_RETURNED_FUNCTIONS:
            return None
        self._next += 1
        ref_id = f"{os.getpid()}.{self._next}"
        self.returned[ref_id] = value  # type: ignore[assignment]
        # The type's name, read without running student code (a function's own
        # __name__ could be a property of a class it pretends to be).
        name = type.__getattribute__(type(value), "__name__")
        return values.CallableRef(ref_id, name if type(name) is str else "function")


def _invoke(channel: Channel, target: Any, request: dict[str, Any]) -> dict[str, Any]:
    before = set(figures.open_figure_numbers())
    args = channel.stubs(request.get("args", ()))
    kwargs = channel.stubs(request.get("kwargs", {}))
    if not isinstance(args, (list, tuple)) or not isinstance(kwargs, dict):
        return {"ok": False, "error": "bad-request", "message": "args must be a list"}
    channel.in_call = True
    try:
        value = target(*args, **kwargs)
    except BaseException as exc:  # anything the student's code raises, SystemExit included
        return {"ok": False, "error": "exception", "type": type(exc).__name__,
                "message": _message(exc), "traceback": student_traceback(exc)}
    finally:
        channel.end_call()
    answer: dict[str, Any] = {"ok": True, "value": value}
    if request.get("figures"):
        answer["figures"] = figures.figures_data(exclude=before)
    return answer


def _call(shell: GradingShell, channel: Channel, request: dict[str, Any]) -> dict[str, Any]:
    name = request.get("name")
    target = shell.user_ns.get(name) if isinstance(name, str) else None
    if target is None or not callable(target):
        kind = "missing" if target is None else "not-callable"
        return {"ok": False, "error": kind, "type": type(target).__name__}
    return _invoke(channel, target, request)


def _call_ref(channel: Channel, request: dict[str, Any]) -> dict[str, Any]:
    target = channel.returned.get(str(request.get("id")))
    if target is None:
        return {"ok": False, "error": "stale-ref",
                "message": "the function belonged to an earlier run of the notebook"}
    return _invoke(channel, target, request)


def _message(exc: BaseException) -> str:
    try:
        return str(exc)[:2000]
    except BaseException:  # hostile __str__
        return "<unprintable exception>"


def handle(shell: GradingShell, output: BoundedText, request: dict[str, Any],
           channel: Channel) -> dict[str, Any]:
    """Answer one request; never raises for anything the student's code does."""
    op = request.get("op")
    if op == "call":
        answer = _call(shell, channel, request)
    elif op == "call-ref":
        answer = _call_ref(channel, request)
    elif op == "figures":
        answer = {"ok": True, "value": figures.figures_data()}
    elif op == "functions":
        answer = {"ok": True, "value": defined_functions(shell)}
    else:
        answer = {"ok": False, "error": "bad-request", "message": f"unknown op {op!r}"}
    answer["stdout"] = output.take()
    return answer


#: the pid of the process that serves the grader (set by protect_channel)
_SERVING: list[int] = []


def protect_channel(sock: socket.socket) -> None:
    """Make ``sock`` this process's alone: closed in every child it forks, never inherited.

    Called once in the sandboxed child before any student code runs. A forked child
    that reaches the worker's own code anyway (a fork that bypassed Python's hooks)
    is stopped by :func:`owns_channel`.
    """
    _SERVING[:] = [os.getpid()]
    sock.set_inheritable(False)  # close-on-exec: no program the student runs gets it
    os.register_at_fork(after_in_child=sock.close)


def owns_channel() -> bool:
    """Whether this process is the one that serves the grader (see :func:`protect_channel`)."""
    return not _SERVING or _SERVING[0] == os.getpid()


def leave_if_forked() -> None:
    """End this process at once if it is a child the student's code forked."""
    if not owns_channel():
        os._exit(0)


def serve(sock: socket.socket, shell: GradingShell, output: BoundedText) -> None:
    """Answer requests until the grader says goodbye or goes away."""
    channel = Channel(sock)
    while True:
        leave_if_forked()
        try:
            request = frames.recv_message(sock)
        except (EOFError, OSError, ProtocolError):
            return
        if not isinstance(request, dict) or request.get("op") == "bye":
            return
        if request.get("op") == "map":
            serve_map(shell, output, request, channel)
            continue
        answer = handle(shell, output, request, channel)
        leave_if_forked()  # a child the call forked, unwound back to here: not its answer
        send_answer(sock, answer, channel)


def serve_map(shell: GradingShell, output: BoundedText, request: dict[str, Any],
              channel: Channel) -> None:
    """Answer a batch: one ``item`` frame per call, in order, then ``map-done``.

    ``{"op": "map", "batch": b, "name": name, "items": [args, ...]}`` calls
    ``name(*args)`` for each item, as one ``call`` request each would (each item's
    answer is framed alone, so the frame limit holds per answer, and an answer that
    cannot be framed is that item's "unsupported" answer). The grader reads each
    answer under the item's own time limit while the next item runs.
    """
    batch, name, items = request.get("batch"), request.get("name"), request.get("items")
    if type(batch) is not int or not isinstance(items, list):
        items = []
    for i, args in enumerate(items):
        answer = _call(shell, channel, {"name": name, "args": args, "kwargs": {}})
        answer.update(op="item", batch=batch, i=i, stdout=output.take())
        leave_if_forked()  # a child the call forked, unwound back to here: not its answer
        send_answer(channel.sock, answer, channel)
    leave_if_forked()
    frames.send_message(channel.sock, {"op": "map-done", "batch": batch, "count": len(items)})


def send_answer(sock: socket.socket, answer: dict[str, Any], channel: Channel | None = None) -> None:
    """Send ``answer``; a value that cannot be framed becomes an 'unsupported' answer
    (with the answer's batch tags, when it answers an item of a batch)."""
    export = channel.export if channel is not None else None
    try:
        frames.send_message(sock, answer, figure_encoder=figures.figure_to_data,
                              callable_encoder=export)
    except ProtocolError as exc:
        tags = {k: answer[k] for k in ("op", "batch", "i") if k in answer}
        frames.send_message(sock, {"ok": False, "error": "unsupported",
                                     "message": str(exc), "stdout": "", **tags})
