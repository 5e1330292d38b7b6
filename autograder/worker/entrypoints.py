"""Replace the entry points of forbidden classes, wherever the class object is reached.

Replacing a class's name in module namespaces leaves the class itself reachable
(``object.__subclasses__()``, an instance's ``type()``, a base of an allowed
class). So the guard changes the class: every function, method, property and
the constructor in its own namespace is replaced, by a refusing stand-in for a
forbidden class, or by a caller-checked entry (:mod:`autograder.worker.gate`) for
one an allowed library needs inside.

Classes written in C or Cython (``scipy.spatial._qhull._Qhull``) are immutable:
``setattr`` on them raises. CPython has no API to change one, and no library
does it, so :func:`_mutable` clears ``Py_TPFLAGS_IMMUTABLETYPE`` for the moment of
the change (with ``ctypes``, before any student code runs); the slots
(``tp_new``, ``tp_init``, ``tp_call``) follow the new attributes as they do for
any class.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import types
from collections.abc import Callable, Iterable, Iterator
from typing import Any

__all__ = ["all_classes", "replace_entry_points"]

_IMMUTABLE = 1 << 8  # Py_TPFLAGS_IMMUTABLETYPE (3.10+)
#: left alone: called by the interpreter with no caller to check, or needed to subclass
_KEEP = frozenset({"__del__", "__init_subclass__", "__subclasshook__", "__class_getitem__",
                   "__set_name__", "__getattribute__", "__getattr__", "__setattr__",
                   "__delattr__", "__dict__", "__weakref__", "__doc__", "__module__",
                   "__qualname__", "__slots__", "__annotations__", "__hash__", "__eq__",
                   "__repr__", "__str__", "__format__", "__sizeof__", "__dir__",
                   "__reduce__", "__reduce_ex__", "__getstate__", "__ne__"})
#: what a forbidden class's constructor and members become
_CALLABLE_KINDS = (types.FunctionType, types.BuiltinFunctionType, types.MethodDescriptorType,
                   types.WrapperDescriptorType, types.ClassMethodDescriptorType,
                   staticmethod, classmethod, property, types.GetSetDescriptorType,
                   types.MemberDescriptorType, functools.cached_property)


def all_classes() -> list[type]:
    """Every class that exists now, found from ``object`` through ``__subclasses__``."""
    found: dict[int, type] = {}
    stack: list[type] = [object]
    while stack:
        cls = stack.pop()
        if id(cls) in found:
            continue
        found[id(cls)] = cls
        try:
            stack.extend(type.__subclasses__(cls))
        except TypeError:
            pass
    return list(found.values())


def replace_entry_points(cls: type, make: Callable[[Any, str], Any], *,
                         constructor: bool = False) -> int:
    """Replace each callable member of ``cls`` by ``make(member, name)``; return how many.

    With ``constructor``, ``cls.__new__`` is replaced even when ``cls`` inherits it,
    so that no instance can be made.
    """
    owner = f"{cls.__module__}.{cls.__qualname__}"
    changes: list[tuple[str, Any]] = []
    for attr, value in list(vars(cls).items()):
        if attr in _KEEP or not isinstance(value, _CALLABLE_KINDS):
            continue
        replacement = _wrap(value, f"{owner}.{attr}", make)
        if replacement is not None:
            changes.append((attr, replacement))
    if constructor and "__new__" not in vars(cls):
        changes.append(("__new__", staticmethod(make(cls.__new__, f"{owner}.__new__"))))
    with _mutable(cls) as writable:
        if not writable:
            return 0
        for attr, replacement in changes:
            try:
                setattr(cls, attr, replacement)
            except (TypeError, AttributeError):
                pass
    return len(changes)


def _wrap(value: Any, name: str, make: Callable[[Any, str], Any]) -> Any:
    if isinstance(value, staticmethod):
        return staticmethod(make(value.__func__, name))
    if isinstance(value, classmethod):
        return classmethod(make(value.__func__, name))
    if isinstance(value, functools.cached_property):
        return functools.cached_property(make(value.func, name))
    if isinstance(value, property):
        return property(*(make(f, name) if f is not None else None
                          for f in (value.fget, value.fset, value.fdel)), value.__doc__)
    if isinstance(value, (types.GetSetDescriptorType, types.MemberDescriptorType)):
        getter = value.__get__
        return property(make(lambda obj: getter(obj, type(obj)), name))
    if isinstance(value, types.BuiltinFunctionType) and value.__name__ == "__new__":
        return staticmethod(make(value, name))
    return make(value, name)


@contextlib.contextmanager
def _mutable(cls: type) -> Iterator[bool]:
    """Let ``setattr`` change ``cls`` for a moment, even when it is an immutable (C) type."""
    flags = cls.__flags__
    if not flags & _IMMUTABLE:
        yield True
        return
    cell = _flags_cell(cls)
    if cell is None:
        yield False
        return
    cell.value = flags & ~_IMMUTABLE
    try:
        yield True
    finally:
        cell.value = flags


def _flags_cell(cls: type) -> ctypes.c_ulong | None:
    offset = _flags_offset()
    if offset is None:
        return None
    cell = ctypes.c_ulong.from_address(id(cls) + offset)
    return cell if cell.value == cls.__flags__ else None


@functools.cache
def _flags_offset() -> int | None:
    """Where ``tp_flags`` sits in a type object: found, not assumed, on four built-in types."""
    probes: Iterable[type] = (int, str, dict, float)
    for offset in range(0, 512, ctypes.sizeof(ctypes.c_void_p)):
        if all(ctypes.c_ulong.from_address(id(t) + offset).value == t.__flags__ for t in probes):
            return offset
    return None
