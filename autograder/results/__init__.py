"""Results: the result model and everything written from it.

The frozen dataclasses of a submission's result, the one writer of a result
folder (:mod:`~autograder.results.store`), the feedback page, the class summary,
the exports (JUnit, Canvas, Gradescope's ``results.json``) and the merge of
shards. Nothing here runs student code or checks.
"""
