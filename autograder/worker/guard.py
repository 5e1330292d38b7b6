"""Make an assignment's forbidden libraries unreachable in the worker, whatever the spelling.

The static scan (``autograder.engine.staticscan``) names a forbidden use with a clear
message, but names can be computed (``importlib.import_module("scipy." + "spatial")``,
``exec`` of a decoded string, ``vars(scipy)[...]``, a private alias inside an
allowed module). This module enforces the rule on what runs:

1. every forbidden module (and its submodules) is taken out of ``sys.modules``
   and off its parent package; a forbidden attribute (``numpy.polyfit``) is
   replaced on its module;
2. every other reference to those objects found in a loaded module's namespace,
   or in a class defined there, is replaced by a :class:`Blocked` stand-in that
   raises :class:`NotAllowedError`, unless the assignment lists the name under
   ``internal_use`` (a library the allowed ones need inside, such as
   ``matplotlib.path`` for drawing);
3. an audit hook (PEP 578; once added it cannot be removed) refuses any new
   import of a forbidden module, by any route through the import system, and the
   ``gc`` functions that could dig the originals out of memory;
4. the grader also keeps the forbidden packages' folders out of the sandbox's
   readable paths, so their files cannot be loaded by hand.

A call that reaches a blocked object raises :class:`NotAllowedError`, which the
grader turns into a "forbidden" verdict with the assignment's reason.
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Iterable, Sequence
from typing import Any

__all__ = ["Blocked", "NotAllowedError", "forbid"]

#: audit events that would hand out references to blocked objects
_DIGGING = frozenset({"gc.get_objects", "gc.get_referrers", "gc.get_referents"})


class NotAllowedError(ImportError):
    """Raised when student code reaches a library the assignment forbids."""


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

    __call__ = _refuse
    __getattr__ = _refuse
    __iter__ = _refuse
    __getitem__ = _refuse

    def __repr__(self) -> str:
        return f"<not allowed: {object.__getattribute__(self, '_name')}>"


def forbid(names: Sequence[str], *, internal_use: Sequence[str] = (), reason: str = "") -> list[str]:
    """Apply the assignment's ``forbid`` list to this process; return one note per step."""
    if not names:
        return []
    # Names that allowed libraries need inside stay loaded and importable: for them
    # the static scan's verdict is the rule (said in the assignment's toml).
    kept = tuple(internal_use)
    prefixes = tuple(name for name in names if not _matches(name, kept))
    for name in prefixes:  # load what exists, so that it can be blocked in place
        try:
            importlib.import_module(name)
        except Exception:  # not installed, an attribute, or fails to import: nothing to load
            pass
    modules, objects = _targets(prefixes)
    # Loaded forbidden modules stay loaded (allowed code may import them at call time,
    # as matplotlib's Triangulation does with its qhull module even when it is given
    # the triangles): their classes and functions are blocked in place instead, so
    # every route to the module object finds only stand-ins.
    poison = {id(obj): name for name, obj in objects.items()}
    replaced = _replace_aliases(poison, set(), reason)
    for name in objects:
        _set_on_parent(name, Blocked(name, reason))
    sys.addaudithook(_audit_hook(prefixes, reason))
    return [f"forbidden at run time: {', '.join(prefixes)} ({len(modules)} loaded modules "
            f"blocked in place, {replaced} references replaced)"]


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


def _replace_aliases(poison: dict[int, str], gone: set[str], reason: str) -> int:
    """Replace references to poisoned objects in loaded modules and their classes."""
    count = 0
    for modname, module in list(sys.modules.items()):
        if module is None or modname in gone:
            continue
        for owner, namespace in _namespaces(module):
            for key, value in list(namespace.items()):
                name = poison.get(id(value))
                if name is None:
                    continue
                try:
                    if isinstance(owner, type):
                        setattr(owner, key, Blocked(name, reason))
                    else:
                        namespace[key] = Blocked(name, reason)
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


def _audit_hook(prefixes: tuple[str, ...], reason: str) -> Any:
    def hook(event: str, args: tuple[Any, ...]) -> None:
        if event == "import" and args and isinstance(args[0], str) and _matches(args[0], prefixes):
            raise NotAllowedError(f"`{args[0]}` is not allowed in this assignment. {reason}".strip())
        if event in _DIGGING:
            raise NotAllowedError(f"{event} is not available while grading.")
    return hook
