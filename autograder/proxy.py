"""The ``student`` object that checks call: every attribute is a function across the boundary.

``student.convex_hull(points)`` sends the call to the sandboxed worker with a
time limit and returns the value rebuilt as plain data on this side.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from autograder.errors import ForbiddenUse, MissingFunction


class CallTarget(Protocol):
    """What the proxy needs from a session (a real worker or an unreadable notebook)."""

    def call(self, name: str, args: Any, kwargs: dict[str, Any], *, timeout: float,
             figures: bool = False) -> tuple[Any, list[Any]]: ...

    def figures(self, *, timeout: float) -> list[Any]: ...


@dataclass
class CallLog:
    """Which student functions the current check called (for the forbidden-name rule)."""

    names: list[str] = field(default_factory=list)


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
        return self._target.call(name, args, kwargs, timeout=timeout or self._timeout,
                                 figures=figures)

    def figures(self) -> list[Any]:
        """Data of the figures the notebook left open (one dict per figure)."""
        return self._target.figures(timeout=self._timeout)
