"""Who is calling: student code, a library in between, or code that needs a forbidden name.

The guard (:mod:`autograder.worker.guard`) lets a library use a forbidden module
it needs inside (``[rules] internal_use``, such as ``matplotlib.bezier`` for
drawing patches) while refusing the same call from student code. The caller is
read from the frames, walking from the frame that made the call towards the
bottom of the stack:

* a frame running a code object of a module that needs the name (one that held
  a reference to it when the guard was applied), with that module's own globals,
  decides "library": code objects cannot be forged, only reused, and reuse with
  other globals does not count;
* a frame running code from a file of the Python installation (the standard
  library, site-packages, the grader's own package) is a go-between
  (``np.vectorize``, ``functools``): the walk goes on below it;
* any other frame (a notebook cell, ``exec`` of a string, a file the student
  wrote) decides "student".

A file name can be forged (``compile(src, numpy.__file__, "exec")``), but a
forged go-between only makes the walk go on to the student's frame below it.
"""

from __future__ import annotations

import os
import sys
import sysconfig
import types
from collections.abc import Iterable
from typing import Any

__all__ = ["Callers", "code_objects"]

#: what a walk decides
LIBRARY, STUDENT, NOBODY = "library", "student", "nobody"


def _library_roots() -> tuple[str, ...]:
    paths = sysconfig.get_paths()
    roots = {paths[k] for k in ("stdlib", "platstdlib", "purelib", "platlib") if k in paths}
    for name in ("numpy", "scipy", "matplotlib", "IPython", "autograder"):
        module = sys.modules.get(name)
        origin = getattr(module, "__file__", None)
        if origin:  # the package's folder; for the libraries, the folder they sit in
            folder = os.path.dirname(os.path.realpath(origin))
            roots.add(folder if name == "autograder" else os.path.dirname(folder))
    return tuple(sorted(os.path.join(r, "") for r in roots)) + ("<frozen ",)


class Callers:
    """Decide who called, from the code objects of the modules that need forbidden names."""

    def __init__(self, needing: Iterable[types.ModuleType]) -> None:
        self._roots = _library_roots()
        #: id(code) -> (code, the globals it must run with); the code is kept alive so
        #: that its id is never reused by a code object made later
        self._trusted: dict[int, tuple[types.CodeType, dict[str, Any]]] = {}
        for module in needing:
            for code, namespace in code_objects(module):
                self._trusted[id(code)] = (code, namespace)

    def __len__(self) -> int:
        return len(self._trusted)

    def decide(self, frame: types.FrameType | None) -> str:
        """``LIBRARY``, ``STUDENT`` or ``NOBODY`` (only go-betweens down to the bottom)."""
        depth = 0
        while frame is not None and depth < 500:
            code = frame.f_code
            known = self._trusted.get(id(code))
            if known is not None and known[0] is code and frame.f_globals is known[1]:
                return LIBRARY
            if not code.co_filename.startswith(self._roots):
                return STUDENT
            frame, depth = frame.f_back, depth + 1
        return NOBODY if frame is None else STUDENT


def code_objects(module: types.ModuleType) -> list[tuple[types.CodeType, dict[str, Any]]]:
    """Every code object of the functions and classes in ``module`` (nested and decorated
    ones too), each with the globals its function runs with."""
    found: list[tuple[types.CodeType, dict[str, Any]]] = []
    seen: set[int] = set()
    try:
        values = list(vars(module).values())
    except TypeError:
        return found
    classes = [v for v in values if isinstance(v, type)
               and getattr(v, "__module__", None) == module.__name__]
    for cls in classes:
        values += list(vars(cls).values())
    for value in values:
        for function in _functions(value):
            _nested(function.__code__, function.__globals__, found, seen)
    return found


def _functions(value: Any) -> list[types.FunctionType]:
    """The functions behind ``value``: through methods, properties and decorators."""
    if isinstance(value, (staticmethod, classmethod)):
        value = value.__func__
    if isinstance(value, property):
        stack = [f for f in (value.fget, value.fset, value.fdel) if f is not None]
    else:
        stack = [value]
    out: list[types.FunctionType] = []
    while stack and len(out) < 20:
        value = stack.pop()
        if not isinstance(value, types.FunctionType) or any(value is f for f in out):
            continue
        out.append(value)
        stack.append(getattr(value, "__wrapped__", None))  # functools.wraps
        stack.extend(c.cell_contents for c in value.__closure__ or () if _filled(c))
    return out


def _filled(cell: Any) -> bool:
    try:
        cell.cell_contents
    except ValueError:  # an empty cell
        return False
    return True


def _nested(code: types.CodeType, namespace: dict[str, Any],
            found: list[tuple[types.CodeType, dict[str, Any]]], seen: set[int]) -> None:
    stack: list[Any] = [code]
    while stack:
        code = stack.pop()
        if not isinstance(code, types.CodeType) or id(code) in seen:
            continue
        seen.add(id(code))
        found.append((code, namespace))
        stack.extend(c for c in code.co_consts if isinstance(c, types.CodeType))
