"""A peer at the far end of a socket pair, standing for what student code can do with the
worker's descriptor: raw frames, and a CPU clock that never moves (so only the wall-clock
backstop ends a wait)."""

from __future__ import annotations

import json
import struct
from typing import Any


class IdleClock:
    """A child that uses no CPU: only the wall-clock backstop can end a wait."""

    def start(self) -> None: ...
    def used(self) -> float: return 0.0
    def own(self) -> float: return 0.0
    def queued(self) -> float: return 0.0
    def close(self) -> None: ...


def frame(value: Any) -> bytes:
    """``value`` (plain JSON) as one frame without buffers, written by hand."""
    header = json.dumps({"v": value, "bufs": []}).encode()
    return struct.pack(">I", len(header)) + header
