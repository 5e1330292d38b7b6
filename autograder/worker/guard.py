"""Make an assignment's forbidden libraries unusable in the worker, whatever the route.

The static scan (``autograder.engine.staticscan``) names a forbidden use with a clear
message, but names can be computed (``importlib.import_module("scipy." + "spatial")``,
``exec`` of a decoded string, ``vars(scipy)[...]``, a private alias inside an
allowed module) and objects can be reached without a name (``__subclasses__``).
This module enforces the rule on what runs:

1. every reference to a forbidden module's classes and functions (or to a
   forbidden attribute such as ``numpy.polyfit``) in a loaded module's namespace,
   or in a class defined there, is replaced by a :class:`Blocked` stand-in that
   raises :class:`NotAllowedError`;
2. every class defined in a forbidden module, found from ``object`` through
   ``__subclasses__``, has its constructor and members replaced by stand-ins
   (:mod:`autograder.worker.entrypoints`; C and Cython classes too);
3. names an allowed library needs inside (``[rules] internal_use``, such as
   ``matplotlib.bezier`` for drawing) stay usable by that library only: their
   functions and methods become caller-checked entries (:mod:`autograder.worker.gate`,
   :mod:`autograder.worker.callers`);
4. an audit hook (PEP 578; once added it cannot be removed) refuses any new
   import of a forbidden module, re-running or reading its files, and the ways to
   dig objects or frames out of memory (``gc``, tracers, ``ctypes``);
5. the grader also keeps the forbidden packages' folders out of the sandbox's
   readable paths, so their files cannot be loaded by hand.

A call that reaches a blocked object raises :class:`NotAllowedError`, which the
grader turns into a "forbidden" verdict with the assignment's reason.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.util
import os
import sys
import types
from collections.abc import Iterable, Sequence
from typing import Any

from autograder.worker import entrypoints, gate
from autograder.worker.callers import Callers
from autograder.worker.gate import NotAllowedError

__all__ = ["Blocked", "NotAllowedError", "forbid"]

class Blocked:
    """Stands where a forbidden module, class or function was."""

    __slots__ = ("_name", "_reason")

    def __init__(self, name: str, reason: str) -> None:
        object.__setattr__(self, "_name", name)
        object.__setattr__(self, "_reason", reason)

    def _refuse(self, *args: Any, **kwargs: Any) -> Any:
        name = object.__getattribute__(self, "_name")
        reason = object.__getattribute__(self, "_reason")
        raise NotAllowedError(f"`{name}` is not allowed in this assignment. {reason}".strip())

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") and attr.endswith("__"):  # metadata lookups (staticmethod's)
            raise AttributeError(attr)
        return self._refuse()

    __call__ = _refuse
    __iter__ = _refuse
    __getitem__ = _refuse

    def __repr__(self) -> str:
        return f"<not allowed: {object.__getattribute__(self, '_name')}>"


def forbid(names: Sequence[str], *, internal_use: Sequence[str] = (), reason: str = "") -> list[str]:
    """Apply the assignment's ``forbid`` list to this process; return one note per step."""
    if not names:
        return []
    kept = tuple(internal_use)
    prefixes = tuple(name for name in names if not _matches(name, kept))
    for name in (*prefixes, *kept):  # load what exists, so that it can be blocked in place
        try:
            importlib.import_module(name)
        except Exception:  # not installed, an attribute, or fails to import: nothing to load
            pass
    modules, objects = _targets(prefixes)
    inner_modules, inner_objects = _targets(kept)
    # Loaded forbidden modules stay loaded (allowed code may import them at call time,
    # as matplotlib's Triangulation does with its qhull module even when it is given
    # the triangles): their classes and functions are blocked in place instead, so
    # every route to the module object finds only stand-ins.
    callers = Callers(_needing(inner_modules, inner_objects))
    make_entry, start = gate.install(callers, prefixes, _files(modules, inner_modules), reason)
    poison = {id(obj): (name, None) for name, obj in objects.items()}
    poison.update({id(obj): (name, make_entry(obj, name)) for name, obj in inner_objects.items()
                   if isinstance(obj, (types.FunctionType, types.BuiltinFunctionType))})
    replaced = _replace_aliases(poison, reason)
    for name, obj in objects.items():
        _set_on_parent(name, Blocked(name, reason))
    classes = _classes(prefixes, objects), _classes(kept, inner_objects)
    for cls in classes[0]:
        entrypoints.replace_entry_points(cls, lambda _obj, name: Blocked(name, reason),
                                         constructor=True)
    for cls in classes[1]:
        entrypoints.replace_entry_points(cls, make_entry)
    start()  # once added, the hook cannot be removed
    return [f"forbidden at run time: {', '.join(prefixes) or '-'} ({len(modules)} loaded modules "
            f"blocked in place, {replaced} references replaced, {len(classes[0])} classes "
            f"refused); library use only: {', '.join(kept) or '-'} ({len(classes[1])} classes, "
            f"{len(callers)} library functions may call them)"]


def _classes(prefixes: tuple[str, ...], objects: dict[str, Any]) -> list[type]:
    """The classes defined under ``prefixes`` (however reached), and those named directly."""
    if not prefixes:
        return []
    named = {id(v): v for v in objects.values() if isinstance(v, type)}
    found = [c for c in entrypoints.all_classes()
             if id(c) in named or _matches(str(getattr(c, "__module__", "")), prefixes)]
    return sorted(found, key=lambda c: len(c.__mro__))


def _needing(modules: dict[str, types.ModuleType],
             objects: dict[str, Any]) -> list[types.ModuleType]:
    """The loaded modules that may call an internal name: those of its package, and any
    other that holds a reference to it.

    The whole package, because its modules call methods on instances other modules
    made (``matplotlib.axes`` asks ``BezierSegment.axis_aligned_extrema`` of the
    curves of a patch's path).
    """
    wanted = {id(v) for v in (*modules.values(), *objects.values())}
    packages = tuple({n.partition(".")[0] for n in (*modules, *objects)})
    needing: dict[int, types.ModuleType] = {id(m): m for m in modules.values()}
    for name, module in list(sys.modules.items()):
        if module is None or id(module) in needing:
            continue
        if _matches(name, packages):
            needing[id(module)] = module
            continue
        for _owner, namespace in _namespaces(module):
            if any(id(v) in wanted for v in list(namespace.values())):
                needing[id(module)] = module
                break
    return list(needing.values())


def _files(*groups: dict[str, types.ModuleType]) -> frozenset[str]:
    """The files (and package folders) of the forbidden modules: not to be read or re-run."""
    found: set[str] = set()
    for group in groups:
        for module in group.values():
            origin = getattr(module, "__file__", None)
            if not isinstance(origin, str):
                continue
            found.add(os.path.realpath(origin))
            with contextlib.suppress(ValueError, NotImplementedError):
                found.add(os.path.realpath(importlib.util.cache_from_source(origin)))
            for folder in getattr(module, "__path__", None) or ():
                found.add(os.path.realpath(folder))
    return frozenset(found)


def _matches(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def _targets(prefixes: tuple[str, ...]) -> tuple[dict[str, types.ModuleType], dict[str, Any]]:
    """Loaded forbidden modules by name, and forbidden objects (attributes, module members)."""
    modules = {name: mod for name, mod in list(sys.modules.items())
               if mod is not None and _matches(name, prefixes)}
    objects: dict[str, Any] = {}
    for entry in prefixes:
        owner_name, _, attr = entry.rpartition(".")
        owner = sys.modules.get(owner_name)
        if entry not in modules and owner is not None and attr and hasattr(owner, attr):
            value = getattr(owner, attr)
            if isinstance(value, types.ModuleType):
                modules[entry] = value
            else:
                objects[entry] = value
    for name, module in modules.items():  # the classes and functions they define
        for attr, value in list(vars(module).items()):
            if not callable(value) or isinstance(value, types.ModuleType):
                continue
            home = str(getattr(value, "__module__", "") or "")
            # C functions of an extension module name the module as their __self__.
            if _matches(home, prefixes) or getattr(value, "__self__", None) is module:
                objects.setdefault(f"{name}.{attr}", value)
    return modules, objects


def _replace_aliases(poison: dict[int, tuple[str, Any]], reason: str) -> int:
    """Replace references to poisoned objects in loaded modules and their classes.

    ``poison`` maps ``id(object)`` to its name and its replacement (``None``: a
    refusing :class:`Blocked`).
    """
    count = 0
    for modname, module in list(sys.modules.items()):
        if module is None:
            continue
        for owner, namespace in _namespaces(module):
            for key, value in list(namespace.items()):
                found = poison.get(id(value))
                if found is None:
                    continue
                name, replacement = found
                stand_in = Blocked(name, reason) if replacement is None else replacement
                try:
                    if isinstance(owner, type):
                        setattr(owner, key, stand_in)
                    else:
                        namespace[key] = stand_in
                    count += 1
                except (TypeError, AttributeError):  # a read-only class (a C type): leave it
                    pass
    return count


def _namespaces(module: types.ModuleType) -> Iterable[tuple[Any, Any]]:
    """``(owner, mapping)``: the module's namespace, and those of the classes it defines."""
    try:
        namespace = vars(module)
    except TypeError:
        return []
    found: list[tuple[Any, Any]] = [(module, namespace)]
    for value in list(namespace.values()):
        if isinstance(value, type) and getattr(value, "__module__", None) == module.__name__:
            found.append((value, vars(value)))
    return found


def _set_on_parent(name: str, value: Any) -> None:
    parent_name, _, attr = name.rpartition(".")
    parent = sys.modules.get(parent_name)
    if parent is None or not attr:
        return
    try:
        if value is None:
            if attr in vars(parent):
                delattr(parent, attr)
        else:
            setattr(parent, attr, value)
    except (AttributeError, TypeError):
        pass
