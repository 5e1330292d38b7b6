"""The untrusted side: the warm parent that forks one sandboxed child per submission.

Nothing in this package imports the checks, :mod:`reference`, or the grader's
result code; it talks to the grader only through the boundary
(:mod:`autograder.boundary.frames` and :mod:`autograder.boundary.codec`).
"""
