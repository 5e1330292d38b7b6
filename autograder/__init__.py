"""Autograder for numerical-methods notebooks.

The grader (this package, minus :mod:`autograder.worker`) is the trusted side:
it holds the hidden checks and computes every verdict. Student code runs only
in the worker process started by :mod:`autograder.session`.
"""

__version__ = "0.1.0"
