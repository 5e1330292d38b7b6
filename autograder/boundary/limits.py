"""The limits both the codec and the framing hold a message to, and the one size they share.

A frame (:mod:`autograder.boundary.frames`) is refused above
:data:`MAX_FRAME_BYTES`; a value (:mod:`autograder.boundary.codec`) above
:data:`MAX_DEPTH` levels or :data:`MAX_ITEMS` nodes. The codec keeps its own
value limits (strings, ints, array dimensions) beside the code that applies them.
Like the rest of the boundary, this module imports only the standard library.
"""

from __future__ import annotations

import struct

__all__ = ["MAX_FRAME_BYTES", "MAX_DEPTH", "MAX_ITEMS", "MAX_CELLS", "BUFFER_PREFIX"]

#: Largest frame (length prefix, header, buffers and their prefixes) in bytes.
MAX_FRAME_BYTES = 64 * 2**20
#: Deepest nesting of containers (list, tuple, dict, figure) in a value.
MAX_DEPTH = 32
#: Most value nodes in one tree.
MAX_ITEMS = 1_000_000

#: Most code cells a notebook may have to be run. The worker reports every cell in one
#: frame (a report is about 8 nodes) and announces each cell with a frame of its own;
#: 20,000 is far above any real notebook and keeps that report far below MAX_ITEMS.
MAX_CELLS = 20_000

#: The ``>Q`` length before each buffer in a frame: the framing writes and reads it,
#: the codec counts it in a result's size.
BUFFER_PREFIX = struct.Struct(">Q")
