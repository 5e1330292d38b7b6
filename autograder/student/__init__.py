"""What a student runs inside their notebook: ``check()`` and ``submit()``.

``from autograder import check`` reaches :func:`autograder.student.inline.check`
(the package root answers the two names lazily). Both run in the student's own
kernel, on the student's own machine, where only the release exists: the public
checks, never a hidden check or a solution.
"""
