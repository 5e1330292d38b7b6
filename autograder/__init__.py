"""Autograder for numerical-methods notebooks.

The grader (this package, minus :mod:`autograder.worker`) is the trusted side:
it holds the hidden checks and computes every verdict. Student code runs only
in the worker process started by :mod:`autograder.engine.slot`.
"""

import sys as _sys

__version__ = "0.1.0"

# nbformat imports jsonschema, and jsonschema imports the optional `rfc3987_syntax`
# when it is installed (it comes with jupyter's `jsonschema[format-nongpl]`). That
# module compiles a Lark grammar at import: 1.3 s of CPU, more than the rest of a
# command's start-up, in the command and again in every spawned grading slot. The
# grammar only serves jsonschema's "iri" format checker; nbformat validates notebooks
# without any format checker, so verdicts and warnings are the same without it.
# Marking it absent (jsonschema imports it under `suppress(ImportError)`) keeps it out
# of every process that imports numgrade. A module that already imported it keeps it.
_sys.modules.setdefault("rfc3987_syntax", None)  # type: ignore[arg-type]


# Check files written before the engine was laid out in rooms import three modules by
# their old names. They keep working: each old name is the module where the code now
# lives (the same module object, not a copy). New check files import everything from
# `autograder.checks`. No library does this aliasing; importlib's finder protocol is
# the documented way to answer for a module name that has no file of its own.
_MOVED = {
    "autograder.callbacks": "autograder.engine.callbacks",
    "autograder.compare": "autograder.checks.compare_arrays",
    "autograder.curves": "autograder.checks.compare_curves",
}


class _MovedModuleFinder:
    """Answers an old module name with the module that now holds its code."""

    @staticmethod
    def find_spec(name: str, path: object = None, target: object = None) -> object:
        if name not in _MOVED:
            return None
        from importlib.machinery import ModuleSpec

        return ModuleSpec(name, _MovedModuleFinder)

    @staticmethod
    def create_module(spec: object) -> object:
        from importlib import import_module

        return import_module(_MOVED[spec.name])  # type: ignore[attr-defined]

    @staticmethod
    def exec_module(module: object) -> None:
        """Nothing to run: the module was imported under its own name."""


if _MovedModuleFinder not in _sys.meta_path:
    _sys.meta_path.append(_MovedModuleFinder)  # type: ignore[arg-type]


#: names the package root answers lazily (PEP 562): ``from autograder import check`` in a
#: student's notebook, without importing the grader when ``autograder`` alone is imported
_LAZY = {"check": "autograder.student.inline", "submit": "autograder.student.inline"}


def _while_graded(*args: object, **kwargs: object) -> None:
    """check() and submit() as the grader's worker runs them: nothing to do (the grader
    is what is running), and nothing of the grader is importable there."""
    print("(check() and submit() do nothing while the notebook is being graded.)")


def __getattr__(name: str) -> object:
    if name not in _LAZY:
        raise AttributeError(f"module 'autograder' has no attribute {name!r}")
    if "autograder.worker" in _sys.modules:  # the untrusted process running a submission
        return _while_graded
    from importlib import import_module

    return getattr(import_module(_LAZY[name]), name)
