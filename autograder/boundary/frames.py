"""Frames on a socket: one value's tree and buffers as one length-prefixed message.

Used by both sides, the trusted grader and the untrusted worker; like the codec
(:mod:`autograder.boundary.codec`, which turns values into trees and buffers and
back) it imports only the standard library, the rest of the boundary and
:mod:`autograder.errors`. :func:`send_message` and :func:`recv_message` encode
or decode and frame in one call.

Frame
-----
``>I`` length of the header, the UTF-8 (in fact ASCII) JSON header
``{"v": tree, "bufs": [len0, len1, ...]}``, then for each buffer its ``>Q``
length and its bytes. The lengths are in the header *and* before each buffer:
the header copy lets the receiver check the frame's total size against
``max_bytes`` before reading any payload; the prefixes must agree with it.

Errors on receiving: :class:`~autograder.errors.ProtocolError` for a
malformed or oversized frame, :class:`EOFError` when the peer closed the
connection (before or inside a frame), :class:`TimeoutError` when ``timeout``
ran out. After any of these the stream is out of step: close the connection.
"""

from __future__ import annotations

import collections
import json
import socket
import struct
import time
from collections.abc import Callable, Sequence
from typing import Any

from autograder.boundary.codec import (
    Buffer,
    CallableEncoder,
    FigureEncoder,
    Tree,
    decode,
    encode,
    nbytes,
    short_repr,
    size_text,
)
from autograder.boundary.limits import BUFFER_PREFIX, MAX_DEPTH, MAX_FRAME_BYTES, MAX_ITEMS
from autograder.errors import ProtocolError

__all__ = ["send_frame", "recv_frame", "send_message", "recv_message", "Waiter"]

#: called when the peer's side is full: returns once ``sock`` is writable again, or
#: raises ``TimeoutError`` (the sender's deadline); see :func:`send_frame`
Waiter = Callable[[socket.socket], None]

_JSON_INT_CHARS = 320  # a 1024-bit int has 309 digits; longer JSON numbers are rejected
_COALESCE_BYTES = 64 * 1024
_HEADER_LEN = struct.Struct(">I")


def send_frame(
    sock: socket.socket,
    tree: Tree,
    buffers: Sequence[Buffer],
    *,
    max_bytes: int = MAX_FRAME_BYTES,
    wait: Waiter | None = None,
) -> int:
    """Send one frame holding ``tree`` and ``buffers``; return its size in bytes.

    Raises :class:`ProtocolError` before sending anything if the tree is not
    plain JSON or the frame would exceed ``max_bytes``; socket errors
    (``OSError``, ``TimeoutError`` from the socket's own timeout) propagate.
    With ``wait``, no send blocks: each is tried at once, and while the peer does
    not read, ``wait`` decides how long to wait for room (and raises
    ``TimeoutError`` to give up; the stream is then out of step).
    """
    lengths = [nbytes(b) for b in buffers]
    try:
        text = json.dumps({"v": tree, "bufs": lengths}, allow_nan=False, separators=(",", ":"))
    except (TypeError, ValueError, RecursionError) as exc:
        raise ProtocolError(f"tree is not plain JSON: {exc}") from None
    header = text.encode("ascii")  # ensure_ascii: lone surrogates are escaped, not lost
    total = _HEADER_LEN.size + len(header) + sum(BUFFER_PREFIX.size + n for n in lengths)
    if total > max_bytes:
        raise ProtocolError(f"frame of {size_text(total)} exceeds the {size_text(max_bytes)} limit")
    pending = bytearray(_HEADER_LEN.pack(len(header)))
    pending += header
    for data, n in zip(buffers, lengths):
        pending += BUFFER_PREFIX.pack(n)
        if n <= _COALESCE_BYTES:
            pending += data
        else:
            _send_all(sock, pending, wait)
            pending = bytearray()
            _send_all(sock, data, wait)
    if pending:
        _send_all(sock, pending, wait)
    return total


def _send_all(sock: socket.socket, data: Buffer, wait: Waiter | None) -> None:
    """``sock.sendall(data)``, or with ``wait``: sends that never block, ``wait`` in between."""
    if wait is None:
        sock.sendall(data)
        return
    view = memoryview(data).cast("B")
    sent = 0
    while sent < len(view):
        try:
            sent += sock.send(view[sent:], socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            wait(sock)


def recv_frame(
    sock: socket.socket, *, max_bytes: int = MAX_FRAME_BYTES, timeout: float | None = None
) -> tuple[Tree, list[bytearray]]:
    """Receive one frame; return ``(tree, buffers)`` (tree parsed, not yet decoded).

    ``timeout`` is a deadline in seconds for the whole frame (``None``: leave
    the socket's own timeout as it is). Raises :class:`ProtocolError` for a
    malformed frame or one larger than ``max_bytes`` (checked from the header,
    before any payload is read), :class:`EOFError` if the peer closed the
    connection, :class:`TimeoutError` when the deadline passes.
    """
    deadline = None if timeout is None else time.monotonic() + timeout
    previous = sock.gettimeout()
    # The socket's timeout is changed only when a read has to wait for the deadline
    # (see _recv_exactly), and put back only then; a socket that has a timeout of its
    # own is read as before (its reads wait in poll, so they cannot be tried at once).
    waited = [deadline is not None and previous is not None]
    try:
        raw = _recv_exactly(sock, _HEADER_LEN.size, deadline, "frame length", waited)
        (header_len,) = _HEADER_LEN.unpack(raw)
        if _HEADER_LEN.size + header_len > max_bytes:
            limit = size_text(max_bytes)
            raise ProtocolError(
                f"frame header of {size_text(header_len)} exceeds the {limit} limit")
        tree, lengths = _parse_header(_recv_exactly(sock, header_len, deadline, "frame header",
                                                    waited))
        total = _HEADER_LEN.size + header_len + sum(BUFFER_PREFIX.size + n for n in lengths)
        if total > max_bytes:
            limit = size_text(max_bytes)
            raise ProtocolError(f"frame of {size_text(total)} exceeds the {limit} limit")
        buffers = []
        for i, n in enumerate(lengths):
            raw = _recv_exactly(sock, BUFFER_PREFIX.size, deadline, f"length of buffer {i}", waited)
            (announced,) = BUFFER_PREFIX.unpack(raw)
            if announced != n:
                raise ProtocolError(
                    f"buffer {i} is {n} bytes in the header but {announced} in its prefix"
                )
            buffers.append(_recv_exactly(sock, n, deadline, f"buffer {i}", waited))
        return tree, buffers
    finally:
        if waited[0]:
            sock.settimeout(previous)


def send_message(
    sock: socket.socket,
    obj: object,
    *,
    figure_encoder: FigureEncoder | None = None,
    max_depth: int = MAX_DEPTH,
    max_items: int = MAX_ITEMS,
    max_bytes: int = MAX_FRAME_BYTES,
    callable_encoder: CallableEncoder | None = None,
    wait: Waiter | None = None,
) -> int:
    """Encode ``obj`` (see :func:`~autograder.boundary.codec.encode`) and send it as one frame;
    return the frame size.

    Raises :class:`ProtocolError` before sending anything if ``obj`` is over a
    limit. ``wait``: see :func:`send_frame`.
    """
    tree, buffers = encode(
        obj, max_depth=max_depth, max_items=max_items, figure_encoder=figure_encoder,
        callable_encoder=callable_encoder,
    )
    return send_frame(sock, tree, buffers, max_bytes=max_bytes, wait=wait)


def recv_message(
    sock: socket.socket,
    *,
    max_bytes: int = MAX_FRAME_BYTES,
    timeout: float | None = None,
    max_depth: int = MAX_DEPTH,
    max_items: int = MAX_ITEMS,
) -> object:
    """Receive one frame and decode it (see :func:`recv_frame` and
    :func:`~autograder.boundary.codec.decode`)."""
    tree, buffers = recv_frame(sock, max_bytes=max_bytes, timeout=timeout)
    return decode(tree, buffers, max_depth=max_depth, max_items=max_items)


def _recv_exactly(sock: socket.socket, n: int, deadline: float | None, what: str,
                  waited: list[bool]) -> bytearray:
    buf = bytearray(n)
    view = memoryview(buf)
    got = 0
    if deadline is not None and n and not waited[0]:
        # The peer writes a frame with one send, so its bytes are usually here already:
        # take them without a deadline. Setting the socket's timeout for the read (one
        # ioctl each way, and a poll before every read) cost more than the read itself.
        try:
            got = sock.recv_into(view, n, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            got = 0
        else:
            if got == 0:
                raise EOFError(f"connection closed after 0 of {n} bytes of the {what}")
    while got < n:
        if deadline is not None:
            waited[0] = True
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"timed out waiting for the {what} ({got} of {n} bytes read)")
            sock.settimeout(remaining)
        k = sock.recv_into(view[got:])
        if k == 0:
            raise EOFError(f"connection closed after {got} of {n} bytes of the {what}")
        got += k
    return buf


def _parse_header(raw: bytearray) -> tuple[Tree, list[int]]:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ProtocolError("frame header is not UTF-8") from None
    try:
        header = json.loads(
            text,
            parse_constant=_reject_constant,
            parse_int=_parse_int,
            object_pairs_hook=_unique_keys,
        )
    except RecursionError:
        raise ProtocolError("frame header is nested too deeply") from None
    except ValueError as exc:
        raise ProtocolError(f"frame header is not valid JSON: {exc}") from None
    if type(header) is not dict or set(header) != {"v", "bufs"}:
        raise ProtocolError("frame header must be a JSON object with keys 'v' and 'bufs'")
    lengths = header["bufs"]
    if type(lengths) is not list or len(lengths) > MAX_ITEMS:
        raise ProtocolError(f"'bufs' must be a list of at most {MAX_ITEMS} lengths")
    for n in lengths:
        if type(n) is not int or n < 0:
            raise ProtocolError(f"buffer lengths must be non-negative ints; got {short_repr(n)}")
    return header["v"], lengths


def _reject_constant(name: str) -> float:
    raise ProtocolError(f"frame header contains {name}; non-finite floats must use the 'float' tag")


def _parse_int(s: str) -> int:
    if len(s) > _JSON_INT_CHARS:
        raise ProtocolError(f"JSON int of {len(s)} digits; ints over 1024 bits use the 'int' tag")
    return int(s)


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        counts = collections.Counter(k for k, _ in pairs)
        duplicate = next(k for k, n in counts.items() if n > 1)
        raise ProtocolError(f"frame header has the key {short_repr(duplicate)} twice in one object")
    return out
