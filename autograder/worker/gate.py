"""The guard's audit hook: imports, re-execution, frames, and the entries of internal names.

One audit hook (PEP 578; once added it cannot be removed, and no function lists
it) does every run-time refusal of the guard (:mod:`autograder.worker.guard`):

* a new import of a forbidden module, re-running a forbidden module's code
  (``importlib.reload``, ``exec`` of its module code), and student code opening
  its files;
* the ``gc`` functions that hand out references to any object, ``ctypes`` used
  by student code, ``sys.settrace``/``sys.setprofile`` and ``sys._current_frames``;
* the calls of names an allowed library needs inside (``[rules] internal_use``).
  Each such function or method is replaced by an *entry* that only forwards its
  arguments with :func:`sys.audit`; the hook holds the originals (so no attribute,
  closure or global of the entry leads to one), asks
  :class:`~autograder.worker.callers.Callers` who called, and calls the original
  only for the library that needs it. While an original runs, student code it calls
  back into may not take frames (``sys._getframe``, ``tb_frame``, ``gi_frame``):
  the frames above it would lead to the hook's own.
"""

from __future__ import annotations

import os
import sys
import threading
import types
from collections.abc import Callable
from typing import Any

from autograder.worker.callers import LIBRARY, NOBODY, STUDENT, Callers

__all__ = ["EVENT", "NotAllowedError", "install"]

#: the event an entry raises to reach its original
EVENT = "numgrade.guard.call"
#: audit events that would hand out references to any object
_DIGGING = frozenset({"gc.get_objects", "gc.get_referrers", "gc.get_referents"})
#: always refused once the guard is on: a tracer or profiler is handed every frame
_TRACING = frozenset({"sys.settrace", "sys.setprofile", "sys._current_frames"})
_NO_FRAMES = "Taking frames is not allowed in code a library calls back while grading."
#: attributes that hand out frames (raised as ``object.__getattr__``)
_FRAME_ATTRS = frozenset({"tb_frame", "gi_frame", "cr_frame", "ag_frame"})


class NotAllowedError(ImportError):
    """Raised when student code reaches a library the assignment forbids."""


def _entry(key: int, audit: Callable[..., None] = sys.audit) -> Callable[..., Any]:
    def entry(*args: Any, **kwargs: Any) -> Any:
        box: list[Any] = []
        audit(EVENT, key, box, args, kwargs)
        if len(box) != 2:
            raise NotAllowedError("This function is not allowed while grading.")
        if box[0]:
            return box[1]
        raise box[1]
    return entry


_ENTRY_CODE = _entry(0).__code__


def install(callers: Callers, prefixes: tuple[str, ...], files: frozenset[str],
            reason: str) -> tuple[Callable[[Any, str], Callable[..., Any]], Callable[[], None]]:
    """``make_entry(original, name)`` for the internal names, and ``start()`` adding the hook.

    The guard changes classes with ``ctypes`` between the two, which the hook refuses.
    """
    originals: list[tuple[Any, str]] = []
    inside = [0]
    own: set[int] = set()

    def refuse(what: str) -> NotAllowedError:
        return NotAllowedError(f"`{what}` is not allowed in this assignment. {reason}".strip())

    def requester(depth: int = 2) -> types.FrameType | None:
        me = threading.get_ident()
        own.add(me)
        try:  # 0 is this function, 1 the hook, 2 the code that raised the event
            return sys._getframe(depth)
        finally:
            own.discard(me)

    def call(args: tuple[Any, ...]) -> None:
        key, box, a, kw = args
        frame = requester(3)  # below call() and the hook: the entry
        if frame is None or frame.f_code is not _ENTRY_CODE or box:
            return
        original, name = originals[key]
        if callers.decide(frame.f_back) != LIBRARY:
            box += [False, refuse(name)]
            return
        inside[0] += 1
        try:
            value = original(*a, **kw)
        except BaseException as exc:  # handed on without the frames that lead here
            box += [False, _stripped(exc)]
            return
        finally:
            inside[0] -= 1
        box += [True, value]

    def hook(event: str, args: tuple[Any, ...]) -> None:
        if event == EVENT:
            call(args)
        elif event == "sys._getframe":
            if inside[0] and threading.get_ident() not in own and args \
                    and callers.decide(args[0]) == STUDENT:
                raise NotAllowedError(_NO_FRAMES)
        elif event == "object.__getattr__":
            if inside[0] and len(args) > 1 and args[1] in _FRAME_ATTRS \
                    and callers.decide(requester()) == STUDENT:
                raise NotAllowedError(_NO_FRAMES)
        elif event == "import":
            if args and isinstance(args[0], str) and _matches(args[0], prefixes):
                raise refuse(args[0])
        elif event in _DIGGING or event in _TRACING:
            raise NotAllowedError(f"`{event}` is not allowed while grading.")
        elif event.startswith("ctypes.") and callers.decide(requester()) == STUDENT:
            raise NotAllowedError(f"`{event}` is not allowed while grading.")
        elif event == "exec":
            filename = getattr(args[0], "co_filename", "") if args else ""
            if filename and _path_in(filename, files):
                raise refuse(f"re-running {filename}")
        elif event == "open" and args and isinstance(args[0], (str, bytes)):
            if _path_in(args[0], files) and callers.decide(requester()) not in (LIBRARY, NOBODY):
                raise refuse(f"reading {os.fsdecode(args[0])}")

    def make_entry(original: Any, name: str) -> Callable[..., Any]:
        originals.append((original, name))
        entry = _entry(len(originals) - 1)
        for attr in ("__name__", "__qualname__", "__doc__", "__module__"):
            try:
                setattr(entry, attr, getattr(original, attr))
            except (AttributeError, TypeError):
                pass
        return entry

    return make_entry, lambda: sys.addaudithook(hook)


def _matches(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _path_in(path: str | bytes, files: frozenset[str]) -> bool:
    try:
        real = os.path.realpath(os.fsdecode(path))
    except (ValueError, OSError):
        return False
    return real in files or any(real.startswith(f + os.sep) for f in files)


def _stripped(exc: BaseException) -> BaseException:
    """``exc`` and the exceptions chained to it, without tracebacks (they lead to the hook)."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen and len(seen) < 50:
        seen.add(id(current))
        current.__traceback__ = None
        for chained in (current.__cause__, current.__context__):
            if chained is not None and id(chained) not in seen:
                chained.__traceback__ = None
        current = current.__context__ or current.__cause__
    return exc
