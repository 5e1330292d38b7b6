"""The grader's side of the channel, against a peer written here: it never blocks, and it
takes only the frames the protocol allows at each point.

The peer is the far end of a socket pair (what student code can do with the worker's
descriptor); the child's CPU clock is a stand-in that reports no CPU time, so only
the wall-clock backstop ends a wait. The end-to-end attacks, graded by the real CLI,
are in ``test_channel.py``.
"""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from autograder.boundary import frames
from autograder.boundary.limits import MAX_CELLS
from autograder.engine.student_process import NotebookRun, StudentProcess, check_cell_count
from autograder.errors import CallTimeout, NotebookError, ProtocolViolation
from autograder.sandbox.policy import IsolationPolicy
from tests.support.peers import IdleClock, frame

#: generous: a wait that should end after the 1 s backstop but hangs fails the test
HANG = 60.0


def session(sock: socket.socket) -> StudentProcess:
    """A StudentProcess talking to ``sock`` as if its worker had run the notebook."""
    proc = StudentProcess(slot=None, cells=[], data_files=[], policy=IsolationPolicy(),  # type: ignore[arg-type]
                          notebook_timeout=1.0, cpu_budget=100.0)
    proc._sock, proc._clock = sock, IdleClock()  # type: ignore[assignment]
    proc.report = NotebookRun(cells=(), stdout="", functions=("f",), seconds=0.0)
    proc._started_at = time.monotonic()
    proc.on_callback = lambda message: {"op": "callback-result", "ok": True,
                                        "value": np.zeros(4_000_000)}
    return proc


def in_thread(target: Any) -> Any:
    """Run ``target()`` in a thread; fail the test if it is still running after HANG s."""
    box: dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = target()
        except BaseException as exc:  # handed to the test
            box["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(HANG)
    assert not thread.is_alive(), "the grader blocked on a peer that never reads"
    return box


def test_a_send_with_a_waiter_never_blocks_on_a_peer_that_does_not_read() -> None:
    ours, theirs = socket.socketpair()
    calls = []

    def give_up(sock: socket.socket) -> None:
        calls.append(1)
        raise TimeoutError

    with ours, theirs:
        box = in_thread(lambda: frames.send_message(ours, {"x": np.zeros(2_000_000)}, wait=give_up))
    assert isinstance(box.get("error"), TimeoutError) and calls == [1]


def test_a_send_with_a_waiter_delivers_the_whole_frame() -> None:
    ours, theirs = socket.socketpair()
    with ours, theirs:
        value = np.arange(1_000_000, dtype=float)
        reader = threading.Thread(target=lambda: box.update(got=frames.recv_message(theirs)))
        box: dict[str, Any] = {}
        reader.start()
        frames.send_message(ours, {"x": value}, wait=lambda s: None)
        reader.join(HANG)
    assert np.array_equal(box["got"]["x"], value)


def test_a_reply_to_a_callback_the_child_does_not_read_ends_at_the_backstop() -> None:
    """A forged callback request, then no reading: the big reply cannot be delivered."""
    ours, theirs = socket.socketpair()
    with ours, theirs:
        proc = session(ours)

        def child() -> None:
            frames.recv_message(theirs)  # the request
            theirs.sendall(frame({"op": "callback", "id": "g1", "args": [], "kwargs": {}}))

        threading.Thread(target=child, daemon=True).start()
        box = in_thread(lambda: proc.request({"op": "call", "name": "f", "args": [], "kwargs": {}},
                                             timeout=0.05, what="f()"))
    assert isinstance(box.get("error"), CallTimeout), box
    assert "it was waiting" in str(box["error"])


@pytest.mark.parametrize("forged", [
    [{"op": "callback", "id": "g1", "args": [], "kwargs": {}}] * 2000,
    [{"op": "sandbox-broken", "path": "/usr/lib/python3", "error": "Permission denied"}],
    [{"op": "ready", "cells": [], "functions": []}],
    ["not a dict"],
], ids=["unsolicited-callbacks", "sandbox-broken", "ready", "not-a-dict"])
def test_a_frame_the_protocol_does_not_expect_is_the_students_violation(forged: list[Any]) -> None:
    ours, theirs = socket.socketpair()
    with ours, theirs:
        proc = session(ours)
        proc.on_callback = lambda message: {"op": "callback-result", "ok": False, "error": "x"}

        def child() -> None:
            frames.recv_message(theirs)
            theirs.setblocking(False)
            for value in forged:  # written without ever reading the replies
                try:
                    theirs.sendall(frame(value))
                except (BlockingIOError, OSError):
                    return

        threading.Thread(target=child, daemon=True).start()
        box = in_thread(lambda: proc.request({"op": "call", "name": "f", "args": [], "kwargs": {}},
                                             timeout=30.0, what="f()"))
    assert isinstance(box.get("error"), ProtocolViolation), box
    assert "broke the grader's protocol" in str(box["error"])
    # every later call says why, without asking a worker that is gone
    with pytest.raises(ProtocolViolation, match="broke the grader's protocol"):
        proc.report = NotebookRun(cells=(), stdout="", functions=(), seconds=0.0, crashed=True)
        proc.request({"op": "call", "name": "f"}, timeout=1.0, what="f()")


def test_close_does_not_wait_for_a_child_that_does_not_read() -> None:
    ours, theirs = socket.socketpair()
    with theirs:
        ours.setblocking(False)
        try:
            while True:
                ours.send(b"x" * 65536)
        except BlockingIOError:
            pass
        ours.setblocking(True)
        proc = session(ours)
        box = in_thread(proc.close)
    assert "error" not in box, box


def test_a_notebook_of_too_many_cells_is_refused_before_it_runs(tmp_path: Path) -> None:
    check_cell_count(MAX_CELLS)
    with pytest.raises(NotebookError, match="None of its code was run") as caught:
        check_cell_count(340_000)
    assert caught.value.kind == "too-many-cells" and f"{MAX_CELLS:,}" in str(caught.value)
