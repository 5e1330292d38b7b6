"""Authoring: what an instructor does with an assignment before grading.

``release`` (the student notebook), ``scaffold`` (``autograder new``),
``validate`` (the examples against their bands) and the Gradescope zip.
"""
