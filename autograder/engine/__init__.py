"""The engine: grading one submission on the trusted side.

The assignment's definition, the notebook's cells, the static scan, every
forbidden-library rule (in :mod:`autograder.engine.forbidden`), the grading slot and the student's process it starts,
the pytest run of the checks, the proxies through which checks call the
student's functions, and the :class:`~autograder.engine.grader.Grader` that
ties them into one :class:`~autograder.results.model.SubmissionResult`.
"""
