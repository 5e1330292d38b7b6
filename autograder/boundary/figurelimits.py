"""The figure budget both sides hold figure data to: points, artists, strings, pictures.

The worker's encoder (:mod:`autograder.worker.figures`) keeps to it when it reads
a student's figure; the grader (:mod:`autograder.engine.figuredata`) enforces it
again on what it receives, since the worker runs the student's code and may send
anything. Like the rest of the boundary, this module imports only the standard library.
"""

from __future__ import annotations

__all__ = ["MAX_FIGURE_POINTS", "MAX_PNG_PIXELS", "MAX_PNG_BYTES", "MAX_FIGURES", "MAX_AXES",
           "MAX_ARTISTS", "MAX_TEXT_CHARS", "MAX_FIGURE_TEXT", "MAX_NOTES"]

#: points kept over one figure (line points, offsets, path vertices, collection values)
MAX_FIGURE_POINTS = 200_000
#: largest PNG in pixels; a bigger figure is rendered at a lower dpi
MAX_PNG_PIXELS = 4_000_000
#: largest PNG file kept (a plot of MAX_PNG_PIXELS compresses to far less)
MAX_PNG_BYTES = 8 * 2**20
#: figures kept from one answer (pyplot itself warns above 20 open figures)
MAX_FIGURES = 50
#: axes kept per figure, and artists (lines, collections, patches, images, texts) per figure
MAX_AXES = 100
MAX_ARTISTS = 10_000
#: characters kept of one string (label, title, text), and of all strings of a figure
MAX_TEXT_CHARS = 1_000
MAX_FIGURE_TEXT = 100_000
#: notes kept per figure (each at most 200 characters)
MAX_NOTES = 50
