"""Autograder for numerical-methods notebooks.

The grader (this package, minus :mod:`autograder.worker`) is the trusted side:
it holds the hidden checks and computes every verdict. Student code runs only
in the worker process started by :mod:`autograder.session`.
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
