"""A stand-in for the ``otter`` package in the worker, so ``grader.check("q1")`` works.

An otter notebook starts with ``import otter; grader = otter.Notebook("hw.ipynb")``
and calls ``grader.check("q1")`` after each question. The real otter-grader is not
in the student's install and could not read its tests in the sandbox anyway, so
for an otter assignment the child puts this module in ``sys.modules["otter"]``
before the first cell, holding the *public* test cases the trusted side sent at
set-up (``{"questions": {name: [{"name": ..., "source": ...}, ...]}}``). Hidden
cases are never sent here: they reach the worker only in the grading run, after
the notebook ran.

``grader.check`` runs the question's public cases against the caller's globals,
as otter does, and returns a result that IPython echoes as the cell's output
(otter's text: ``q1 results: All test cases passed!`` or each failing case's
message). It never changes a score: the grading run decides that on its own.
``check_all``, ``export``, ``to_pdf`` and ``submit`` do nothing, as in otter's
grading mode.
"""

from __future__ import annotations

import sys
import types
from typing import Any

__all__ = ["CheckResult", "make_module", "install"]

_PASSED = "✅ Test case passed"


class CheckResult:
    """What ``grader.check`` returns: per case, its name, whether it passed, its message."""

    def __init__(self, question: str, cases: list[tuple[str, bool, str]]) -> None:
        self.name = question
        self.cases = cases

    @property
    def passed_all(self) -> bool:
        return all(ok for _, ok, _ in self.cases)

    def summary(self) -> str:
        """otter's ``TestFile.summary`` text."""
        if not self.cases:
            return f"{self.name} has no public tests; it is graded by hidden tests only."
        if self.passed_all:
            return f"{self.name} results: All test cases passed!"
        parts = []
        for name, ok, message in self.cases:
            body = "\n".join("    " + line for line in message.strip().splitlines())
            parts.append(f"{name} result:\n{body}")
        text = "\n\n".join(parts)
        return f"{self.name} results:\n" + "\n".join("    " + line if line else line
                                                     for line in text.splitlines())

    def __repr__(self) -> str:
        return self.summary()


def _run_case(source: str, env: dict[str, Any]) -> tuple[bool, str]:
    try:
        exec(compile(source, "<otter test>", "exec"), env)
    except Exception as exc:  # the student's code fails the case in any way it likes
        try:
            text = str(exc)
        except Exception:  # a hostile __str__
            text = "<unprintable>"
        return False, "❌ " + (text or type(exc).__name__)
    return True, _PASSED


def make_module(spec: dict[str, Any]) -> types.ModuleType:
    """A fresh ``otter`` module whose ``Notebook().check`` runs ``spec``'s public cases."""
    raw = spec.get("questions") if isinstance(spec, dict) else None
    questions: dict[str, list[tuple[str, str]]] = {
        str(q): [(str(c.get("name", q)), str(c.get("source", ""))) for c in cases
                 if isinstance(c, dict)]
        for q, cases in (raw.items() if isinstance(raw, dict) else ()) if isinstance(cases, list)}

    class Notebook:
        """otter's ``Notebook``, as far as a graded notebook uses it."""

        def __init__(self, nb_path: str | None = None, tests_dir: str = "./tests",
                     **kwargs: Any) -> None:
            self._nb_path = nb_path

        def check(self, question: str, global_env: dict[str, Any] | None = None) -> CheckResult:
            if question not in questions:
                raise ValueError(f"{question!r} is not a question of this assignment; the "
                                 f"questions are {', '.join(sorted(questions)) or 'none'}.")
            env = global_env if global_env is not None else sys._getframe(1).f_globals
            return CheckResult(question, [(name, *_run_case(source, env))
                                          for name, source in questions[question]])

        def check_all(self) -> None:
            return None

        def export(self, *args: Any, **kwargs: Any) -> None:
            return None

        def to_pdf(self, *args: Any, **kwargs: Any) -> None:
            return None

        def submit(self, *args: Any, **kwargs: Any) -> None:
            return None

    module = types.ModuleType("otter", "numgrade's stand-in for otter-grader in the worker")
    module.Notebook = Notebook  # type: ignore[attr-defined]
    module.__version__ = "numgrade"  # type: ignore[attr-defined]
    return module


def install(spec: Any) -> None:
    """Make ``import otter`` give the stand-in (in the child, before the first cell)."""
    if isinstance(spec, dict):
        sys.modules["otter"] = make_module(spec)
