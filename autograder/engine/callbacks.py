"""Functions a check passes to student code: the grader's side of a callback.

A check may pass any callable it holds (a numpy ufunc, a lambda or closure of
a hidden check, a ``reference`` function) as an argument of a student call, at
any depth of lists, tuples and dicts. Wrapped in :func:`traced`, the check can
read afterwards how the student's code used it::

    from autograder.engine.callbacks import traced

    f = traced(lambda x: np.exp(x) * np.sin(5 * x))
    values = student.interpolate(f, 20)
    assert f.evaluations <= 21, f"interpolate evaluated f {f.evaluations} times"
    assert np.all(np.isin(f.points, nodes)), "f was evaluated away from the nodes"

How it works: the proxy (:mod:`autograder.engine.proxy`) replaces each callable in the
arguments by a :class:`~autograder.boundary.values.CallableRef` registered in a
:class:`CallbackRegistry` for that one call. The worker hands the student a
stub; calling the stub sends the plain-data arguments back here, where
:meth:`CallbackRegistry.answer` runs the real function and returns plain data.
The function's code never enters the worker. A function declared safe
(``traced(np.sin, safe=True)``, for names in
:data:`~autograder.boundary.values.SAFE_FUNCTIONS`) is evaluated inside the worker
instead, for speed; its calls and points are still counted and reported here.

Misuse is bounded: more than :data:`MAX_CALLBACKS` callbacks in one call are
refused (and the call scores as an exception with a message saying so), the
worker's CPU limit still applies, garbage arguments raise a ``TypeError`` in
the student's own code, and a stub kept and called after its call returned
raises a clear error in the worker.

What is recorded is bounded whatever the student sends: every call is counted
and its evaluation points taken from the argument bound to the function's first
parameter, however it was spelled (``f(t)``, ``f(x=t)``, ``f(*[t])``), up to
:data:`MAX_RECORDED_POINTS`; a call's arguments are kept whole only while they fit
:data:`MAX_RECORD_BYTES` (and the function's :data:`MAX_RECORDED_BYTES`), otherwise
as :class:`ArgumentSummary` (type, shape, dtype and the first few values). Any
exception the function raises on the student's arguments, of any type, is the
student's: it is raised in the student's code as a built-in exception with a
bounded message, and noted for the instructor. Only a misused grader API
(:class:`~autograder.errors.UsageError`) is the check's own error.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from autograder.boundary import limits, values
from autograder.errors import UsageError

__all__ = ["MAX_CALLBACKS", "MAX_RECORDED_POINTS", "MAX_RECORDED_BYTES", "ArgumentSummary",
           "CallRecord", "Traced", "traced", "CallbackRegistry", "holds_callable", "limit_message"]

#: most callbacks answered during one student call (safe functions are not limited)
MAX_CALLBACKS = 200_000
#: most evaluation points a traced function keeps (calls are always counted): 16 MB
MAX_RECORDED_POINTS = 2_000_000
#: most calls whose arguments (whole or summarised) a traced function keeps
MAX_RECORDED_CALLS = 10_000
#: largest arguments of one call kept whole; larger ones are kept as summaries
MAX_RECORD_BYTES = 64 * 2**10
#: most bytes of whole arguments a traced function keeps over all its records
MAX_RECORDED_BYTES = 4 * 2**20
#: values of an array argument a summary keeps, and arguments summarised per call
SUMMARY_VALUES = 8
SUMMARY_ARGUMENTS = 8
#: exceptions a traced function keeps in ``errors`` (each cut to 500 characters)
MAX_KEPT_ERRORS = 100
#: lines for the instructor's log (``grader.log``) per check
MAX_NOTES = 20
#: exception types passed on to the student's code as themselves (others as RuntimeError)
_PASSED_ON = ("TypeError", "ValueError", "ZeroDivisionError", "OverflowError",
              "ArithmeticError", "FloatingPointError", "IndexError", "KeyError")


@dataclass(frozen=True)
class ArgumentSummary:
    """An argument too large to keep whole: what it was, its size and its first values."""

    type: str
    shape: tuple[int, ...]
    dtype: str = ""
    #: the first :data:`SUMMARY_VALUES` values (arrays and strings; empty otherwise)
    sample: tuple[Any, ...] = ()


@dataclass(frozen=True)
class CallRecord:
    """One call of a traced function by student code: its plain-data arguments.

    ``complete`` is False when the arguments were too large to keep: then each of
    the first :data:`SUMMARY_ARGUMENTS` positional and keyword arguments is an
    :class:`ArgumentSummary` (or a number, kept as it is).
    """

    args: tuple[Any, ...]
    kwargs: dict[str, Any]
    complete: bool = True


class Traced:
    """A check's function with a record of how student code called it.

    Calling a :class:`Traced` from the check itself calls the function directly
    and records nothing, so the same object gives the expected values.

    Attributes
    ----------
    calls : int
        How many times student code called it (each call may evaluate many points).
    records : list of CallRecord
        The arguments of the first :data:`MAX_RECORDED_CALLS` calls answered by
        the grader, whole while they fit the byte budgets, summarised beyond
        (safe functions, evaluated in the worker, record points only).
    errors : list of str
        Exceptions the function raised on the student's arguments (for the check
        author; the first :data:`MAX_KEPT_ERRORS`, each cut short).
    """

    def __init__(self, function: Callable[..., Any], *, name: str = "f",
                 safe: bool = False) -> None:
        if not callable(function):
            raise UsageError(f"traced() needs a callable; got {type(function).__name__}.")
        self.function = function
        self.name = str(name)
        self.safe = _safe_name(function) if safe else ""
        self._first = _first_parameter(function)
        self.reset()

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return self.function(*args, **kwargs)

    def __repr__(self) -> str:
        return f"traced({self.name}, calls={self.calls})"

    @property
    def points(self) -> np.ndarray:
        """Every point where student code evaluated the function (the argument bound to
        its first parameter in each call, flattened), in call order; at most
        :data:`MAX_RECORDED_POINTS`."""
        if not self._points:
            return np.zeros(0)
        if len(self._points) > 1:
            self._points = [np.concatenate(self._points)]
        return self._points[0]

    @property
    def evaluations(self) -> int:
        """How many points student code evaluated the function at (all of them,
        also beyond :data:`MAX_RECORDED_POINTS`)."""
        return self._recorded

    def reset(self) -> None:
        """Forget every call recorded so far."""
        self.calls, self.records, self.errors = 0, [], []
        self._points: list[np.ndarray] = []
        self._kept = self._recorded = self._record_bytes = 0
        self.truncated = False

    # -- recording (called by the registry) ------------------------------------
    def record(self, args: tuple[Any, ...], kwargs: dict[str, Any]) -> None:
        """Count one call by student code and keep a bounded record of it; never raises."""
        self.calls += 1
        if len(self.records) < MAX_RECORDED_CALLS:
            self.records.append(self._bounded_record(args, kwargs))
        at = _evaluated_at(self._first, args, kwargs)
        points = _as_points(at)
        if points is None:  # not numbers: still one evaluation, never none
            self._recorded += max(1, _size(at))
        else:
            self._add_points(points)

    def _bounded_record(self, args: tuple[Any, ...], kwargs: dict[str, Any]) -> CallRecord:
        size = _payload_bytes([args, kwargs], MAX_RECORD_BYTES)
        if size <= MAX_RECORD_BYTES and self._record_bytes + size <= MAX_RECORDED_BYTES:
            self._record_bytes += size
            return CallRecord(args, kwargs)
        kept = tuple(_summary(a) for a in args[:SUMMARY_ARGUMENTS])
        named = {str(k)[:100]: _summary(v) for k, v in list(kwargs.items())[:SUMMARY_ARGUMENTS]}
        return CallRecord(kept, named, complete=False)

    def record_tally(self, calls: int, points: np.ndarray, truncated: bool) -> None:
        self.calls += calls
        self._add_points(points.reshape(-1))
        self.truncated = self.truncated or truncated

    def record_error(self, text: str) -> None:
        if len(self.errors) < MAX_KEPT_ERRORS:
            self.errors.append(text[:500])

    def _add_points(self, points: np.ndarray) -> None:
        room = MAX_RECORDED_POINTS - self._kept
        if points.size > room:
            self.truncated = True
        if room > 0:
            # a copy, never a view: a view would keep the student's whole array alive
            kept = np.array(points[:room], dtype=float)
            self._points.append(kept)
            self._kept += kept.size
        self._recorded += points.size


def _first_parameter(function: Callable[..., Any]) -> inspect.Parameter | None:
    """The first parameter of ``function``, if its signature can be read."""
    try:
        parameters = list(inspect.signature(function).parameters.values())
    except (TypeError, ValueError):  # builtins without a signature (some ufuncs)
        return None
    return parameters[0] if parameters else None


def _evaluated_at(first: inspect.Parameter | None, args: tuple[Any, ...],
                  kwargs: dict[str, Any]) -> Any:
    """Where a call evaluates the function: the value its first parameter gets, however
    the call was spelled (positional, keyword, starred), else the first argument given."""
    if first is not None and first.kind is inspect.Parameter.VAR_POSITIONAL:
        return list(args)
    if args:
        return args[0]
    if first is not None and first.name in kwargs and first.kind is not first.VAR_KEYWORD:
        return kwargs[first.name]
    return next(iter(kwargs.values()), None)


def _as_points(value: Any) -> np.ndarray | None:
    """``value`` as a flat float array, or None if it is not numbers (never raises)."""
    try:
        array = np.asarray(value)
        if array.dtype.kind not in "biuf":
            return None
        return array.reshape(-1)
    except Exception:  # ragged lists, ints too large for any dtype, ...: not points
        return None


def _size(value: Any) -> int:
    if isinstance(value, np.ndarray):
        return int(value.size)
    if isinstance(value, (list, tuple, dict)):
        return len(value)
    return 1


def _payload_bytes(value: Any, stop: int, depth: int = 0) -> int:
    """About how many bytes ``value`` holds; counting stops early above ``stop``."""
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, (str, bytes)):
        return len(value)
    if isinstance(value, dict):
        value = list(value.values())
    if isinstance(value, (list, tuple)) and depth < limits.MAX_DEPTH:
        total = 8 * len(value)
        for item in value:
            if total > stop:
                break
            total += _payload_bytes(item, stop - total, depth + 1)
        return total
    return 16


def _summary(value: Any) -> Any:
    """A small stand-in for an argument: numbers as they are, the rest as a summary."""
    if isinstance(value, (bool, int, float, complex, np.generic)) or value is None:
        if isinstance(value, int) and value.bit_length() > 64:
            return ArgumentSummary("int", (), sample=(f"an int of {value.bit_length()} bits",))
        return value
    if isinstance(value, np.ndarray):
        sample = tuple(value.reshape(-1)[:SUMMARY_VALUES].tolist())
        return ArgumentSummary("ndarray", tuple(value.shape), value.dtype.str, sample)
    if isinstance(value, (str, bytes)):
        return ArgumentSummary(type(value).__name__, (len(value),), sample=(value[:64],))
    return ArgumentSummary(type(value).__name__, (_size(value),))


def traced(function: Callable[..., Any], *, name: str = "f", safe: bool = False) -> Traced:
    """Wrap ``function`` so that a check can read how student code called it.

    Parameters
    ----------
    function : callable
        Any callable the check holds; its code stays in the grader.
    name : str
        The name student code sees (in ``repr`` and messages); the function's own
        name is never sent, so a hidden check's helper names stay hidden.
    safe : bool
        Evaluate the function inside the worker (much faster for many scalar
        calls). Only for functions in :data:`autograder.boundary.values.SAFE_FUNCTIONS`
        (pure numpy ufuncs such as ``np.sin``); anything else raises
        :class:`~autograder.errors.UsageError`. The counts and points of a safe
        function are reported by the worker, which the student's code controls:
        when they decide a grade, leave ``safe`` off.
    """
    if isinstance(function, Traced):
        return function
    return Traced(function, name=name, safe=safe)


def _safe_name(function: Callable[..., Any]) -> str:
    for name in sorted(values.SAFE_FUNCTIONS):
        if getattr(np, name.split(".", 1)[1], None) is function:
            return name
    allowed = ", ".join(sorted(values.SAFE_FUNCTIONS))
    raise UsageError(f"{function!r} cannot be evaluated inside the worker: only these numpy "
                     f"functions can ({allowed}). Leave out safe=True to evaluate it in the grader.")


_PLAIN_TYPES = frozenset({type(None), bool, int, float, complex, str, bytes, np.ndarray,
                          np.float64, np.int64})


def _plain_leaf(x: object) -> bool:
    return type(x) in _PLAIN_TYPES or isinstance(
        x, (bool, int, float, complex, str, bytes, np.ndarray, np.generic))


def holds_callable(value: Any, depth: int = 0) -> bool:
    """Whether ``value`` is or contains (in lists, tuples, dicts) something callable;
    fast on long lists of numbers, which most checks pass."""
    if type(value) in _PLAIN_TYPES or depth > limits.MAX_DEPTH:
        return False
    if isinstance(value, dict):
        value = list(value.values())
    if isinstance(value, (list, tuple)):
        kinds = set(map(type, value))  # in C: a long list of numbers or of points is quick
        if kinds <= _PLAIN_TYPES:
            return False
        if kinds <= _PLAIN_TYPES | {tuple, list} and all(
                set(map(type, v)) <= _PLAIN_TYPES for v in value if type(v) in (tuple, list)):
            return False
        return any(type(v) not in _PLAIN_TYPES and holds_callable(v, depth + 1) for v in value)
    return callable(value) and not _plain_leaf(value)


class CallbackRegistry:
    """The functions passed in one student call; answers the worker's callback requests.

    ``notes`` (a list the caller owns) receives a line for every exception a
    function raised on the student's arguments, for the instructor's log.
    """

    def __init__(self, *, max_callbacks: int | None = None,
                 own_ref: Callable[[object], values.CallableRef | None] | None = None,
                 notes: list[str] | None = None) -> None:
        self.functions: dict[str, Traced] = {}
        self.max_callbacks = MAX_CALLBACKS if max_callbacks is None else max_callbacks
        self.callbacks = 0
        self.exceeded = False
        self.check_error: BaseException | None = None
        self.notes: list[str] = [] if notes is None else notes
        self._own_ref = own_ref
        self._ids: dict[int, str] = {}

    def __bool__(self) -> bool:
        return bool(self.functions)

    # -- outgoing ----------------------------------------------------------------
    def export(self, value: Any, _depth: int = 0) -> Any:
        """``value`` with every callable in it (at any depth of lists, tuples and dicts)
        replaced by a ref registered here; plain values are returned as they are."""
        if _depth == 0 and not holds_callable(value):
            return value
        if _plain_leaf(value) or _depth > limits.MAX_DEPTH:
            return value
        if isinstance(value, (list, tuple)):
            items = [self.export(v, _depth + 1) for v in value]
            if type(value) in (list, tuple) and all(a is b for a, b in zip(items, value)):
                return value
            return tuple(items) if isinstance(value, tuple) else items
        if isinstance(value, dict):
            pairs = {k: self.export(v, _depth + 1) for k, v in value.items()}
            if type(value) is dict and all(pairs[k] is v for k, v in value.items()):
                return value
            return pairs
        own = self._own_ref(value) if self._own_ref is not None else None
        if own is not None:  # a function the student returned earlier: the worker has it
            return own
        if callable(value):
            return self._register(traced(value))
        return value

    def _register(self, function: Traced) -> values.CallableRef:
        ref_id = self._ids.get(id(function))
        if ref_id is None:
            ref_id = self._ids[id(function)] = f"g{len(self._ids) + 1}"
            self.functions[ref_id] = function
        return values.CallableRef(ref_id, function.name, function.safe)

    # -- incoming ----------------------------------------------------------------
    def answer(self, message: dict[str, Any]) -> dict[str, Any]:
        """The reply to one callback request from the worker; never raises."""
        try:
            if "tally" in message:
                return self._tally(message["tally"])
            return self._evaluate(message)
        except Exception as exc:  # a bug here must not leave the worker waiting
            self.check_error = self.check_error or exc
            return _error("RuntimeError", "the grader could not evaluate this function")

    def _tally(self, entries: Any) -> dict[str, Any]:
        for entry in entries if isinstance(entries, list) else []:
            function = self.functions.get(str(entry.get("id"))) if isinstance(entry, dict) else None
            calls, points = (entry.get("calls"), entry.get("points")) if function else (0, None)
            if (function is not None and function.safe and type(calls) is int and calls >= 0
                    and isinstance(points, np.ndarray) and points.dtype.kind in "iuf"):
                function.record_tally(calls, points, bool(entry.get("truncated")))
        return {"op": "callback-result", "ok": True, "value": None}

    def _evaluate(self, message: dict[str, Any]) -> dict[str, Any]:
        function = self.functions.get(str(message.get("id")))
        if function is None:
            return _error("TypeError", "this function is not available any more: the call it "
                          "was passed to has returned", error="stale")
        self.callbacks += 1
        if self.callbacks > self.max_callbacks:
            self.exceeded = True
            return _error("RuntimeError", limit_message(function.name, self.max_callbacks),
                          error="limit")
        args, kwargs = message.get("args"), message.get("kwargs")
        if not isinstance(args, list) or not isinstance(kwargs, dict):
            return _error("TypeError", f"`{function.name}` was called with malformed arguments")
        bad = _first_unsupported([args, kwargs])
        if bad is not None:
            return _error("TypeError", f"`{function.name}` accepts numbers and numpy arrays of "
                          f"numbers; it was called with a {bad.type} ({bad.reason})")
        function.record(tuple(args), kwargs)
        try:
            value = function.function(*args, **kwargs)
        except UsageError as exc:  # a misused grader API: the check's own bug, whatever the
            self.check_error = self.check_error or exc  # student passed
            return _error("RuntimeError", "the grader could not evaluate this function")
        except Exception as exc:  # raised on the student's arguments: the student's error
            return self._students_error(function, exc, args, kwargs)
        return {"op": "callback-result", "ok": True, "value": value}

    def _students_error(self, function: Traced, exc: Exception, args: list[Any],
                        kwargs: dict[str, Any]) -> dict[str, Any]:
        """The answer for an exception the function raised on the student's arguments.

        Whatever its type, it is raised in the student's code (as itself when it is a
        usual error of bad arguments, else as ``RuntimeError``), with a message naming
        only the arguments' types and shapes; the instructor's log gets a line, since
        an exception of an unusual type may also be a bug of the check.
        """
        kind = type(exc).__name__[:100]
        text = f"{kind}: {_text(exc)}"
        function.record_error(text)
        passed = ", ".join([_describe(a) for a in args[:SUMMARY_ARGUMENTS]] +
                           [f"{str(k)[:40]}={_describe(v)}"
                            for k, v in list(kwargs.items())[:SUMMARY_ARGUMENTS]])
        if len(self.notes) < MAX_NOTES:
            self.notes.append(f"`{function.name}` raised {text[:500]} when student code called "
                              f"it with {passed or 'no arguments'}")
        return _error(kind if kind in _PASSED_ON else "RuntimeError",
                      f"`{function.name}` raised {kind} when called with "
                      f"{passed or 'no arguments'}: check what your code passes to it")


def limit_message(name: str, limit: int) -> str:
    """The message for a student call that needed more than ``limit`` callbacks."""
    return (f"your code called `{name}` (with the other functions the grader gave it) more than "
            f"{limit:,} times in one call, so the grader stopped answering. Look for a loop that "
            "evaluates the function again and again instead of once per point.")


def _error(kind: str, message: str, *, error: str = "exception") -> dict[str, Any]:
    return {"op": "callback-result", "ok": False, "error": error, "type": kind,
            "message": message}


def _first_unsupported(value: Any, depth: int = 0) -> values.Unsupported | None:
    if type(value) is values.Unsupported:
        return value
    if type(value) is values.CallableRef:
        return values.Unsupported("function", "function", "functions cannot be passed back")
    if depth < limits.MAX_DEPTH and type(value) in (list, tuple):
        for item in value:
            found = _first_unsupported(item, depth + 1)
            if found is not None:
                return found
    if depth < limits.MAX_DEPTH and type(value) is dict:
        return _first_unsupported(list(value.values()), depth + 1)
    return None


def _describe(value: Any) -> str:
    """A short description of an argument the student passed (never its whole value)."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    if isinstance(value, bool) or value is None:
        return repr(value)
    if isinstance(value, int):
        return repr(value) if value.bit_length() <= 64 else f"an int of {value.bit_length()} bits"
    if isinstance(value, (float, complex)):
        return repr(value)
    if isinstance(value, (list, tuple, dict, str, bytes)):
        return f"a {type(value).__name__} of length {len(value)}"
    return f"a {type(value).__name__}"


def _text(exc: BaseException) -> str:
    """``str(exc)``, at most 2,000 characters, whatever its ``__str__`` does."""
    try:
        return str(exc)[:2000]
    except Exception:  # an exception whose message cannot be made (a huge int's digits...)
        return "<no message>"
