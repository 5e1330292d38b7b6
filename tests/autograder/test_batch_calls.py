"""Batched calls (``student.map``): each call keeps its verdict, and a lying worker gains nothing.

Two kinds of peer:

* a real sandboxed worker running a notebook written here: a batch gives, call by
  call, what the same calls one by one give (values, errors and their messages,
  time-outs, crashes, refusals), and the worker's answers are bounded per call;
* a peer written here at the far end of a socket pair (what student code can do
  with the worker's descriptor): forged, repeated, out-of-order or extra answers
  are the student's protocol violation, and a peer that stops reading or writing
  is stopped at the backstop. The grader never hangs and never raises an engine
  error.
"""

from __future__ import annotations

import socket
import struct
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

from autograder.boundary import frames
from autograder.boundary.limits import MAX_FRAME_BYTES
from autograder.engine import student_process
from autograder.engine.proxy import CallLog, Student
from autograder.engine.slot import GradingSlot
from autograder.engine.student_process import NotebookRun, StudentProcess
from autograder.errors import CallTimeout, StudentError, UsageError, WorkerCrashed
from autograder.sandbox.policy import IsolationPolicy
from tests.support.peers import IdleClock, frame
from tests.support.students import running

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the worker needs Linux (fork)")

NOTEBOOK = '''
import json
import os
import time

import numpy as np

def f(a, b=0):
    if a == 3:
        raise ValueError(f"three and {b}")
    if a == 5:
        return object()
    if a == 7:
        while True:
            pass
    if a == 8:
        time.sleep(3600)
    if a == 9:
        os._exit(1)
    if a == 11:
        return np.zeros(9_000_000)
    return a + b

calls = []

def counted(a):
    calls.append(a)
    return len(calls)

def how_many():
    return len(calls)

def size(x):
    return int(np.asarray(x).size)

def apply(g, x):
    return g(x) + 1

def burn(a, b=0):
    t = time.process_time()
    while time.process_time() - t < a:
        pass
    return a

def _socket():
    for fd in map(int, os.listdir("/proc/self/fd")):
        try:
            if os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                return fd
        except OSError:
            pass

def _frame(value):
    header = json.dumps({"v": value, "bufs": []}).encode()
    return len(header).to_bytes(4, "big") + header

def forge(a):
    """Write the answers of this call and the next one before the worker answers."""
    fd = _socket()
    for i in (0, 1):
        os.write(fd, _frame({"op": "item", "batch": a, "i": i, "ok": True, "value": 42,
                             "stdout": ""}))
    return a

def fork_and_answer(a):
    if os.fork() == 0:
        return 99  # the child unwinds into the worker's loop: it must not answer
    os.wait()
    return a
'''

#: the verdict of one call, as a check sees it: ("value", v) or (error type, message)
Verdict = tuple[str, Any]


def verdicts_of(results: Iterator[Any], count: int) -> list[Verdict]:
    out: list[Verdict] = []
    for _ in range(count):
        try:
            out.append(("value", next(results)))
        except StudentError as exc:
            out.append((type(exc).__name__, str(exc)))
    return out


def one_by_one(student: Student, name: str, items: list[tuple[Any, ...]]) -> list[Verdict]:
    out: list[Verdict] = []
    for args in items:
        try:
            out.append(("value", student.call(name, *args)[0]))
        except StudentError as exc:
            out.append((type(exc).__name__, str(exc)))
    return out


def process_of(student: Student) -> StudentProcess:
    return student._target  # type: ignore[return-value]


@pytest.fixture(scope="module")
def slot() -> Iterator[GradingSlot]:
    with GradingSlot() as worker:
        yield worker


# -- a real worker: the same verdicts as one by one -------------------------------------
@pytest.mark.parametrize("items", [
    [(1, 2), (3, 4), (5,), (2,), (11,), (0, 0)],
    [(1,), (7, 1), (2,), (7,), (4,)],
    [(1,), (9,), (2,), (9,), (4,)],
], ids=["errors-and-values", "time-outs", "crashes"])
def test_a_batch_gives_each_call_the_verdict_it_gets_alone(slot: GradingSlot,
                                                            items: list[tuple[Any, ...]]) -> None:
    with running(slot, NOTEBOOK, timeout=0.5) as student:
        alone = one_by_one(student, "f", items)
    with running(slot, NOTEBOOK, timeout=0.5) as student:
        batched = verdicts_of(student.map("f", items), len(items))
        restarts = process_of(student).restarts
    assert batched == alone
    kinds = {kind for kind, _ in batched}
    assert "value" in kinds and len(kinds) > 1, batched
    if "CallTimeout" in kinds or "WorkerCrashed" in kinds:
        assert restarts >= 1  # the calls after the failure went to a new worker


def test_a_function_the_notebook_lacks_fails_every_item(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK) as student:
        assert [kind for kind, _ in verdicts_of(student.map("nope", [(1,), (2,)]), 2)] == [
            "MissingFunction", "MissingFunction"]


def test_a_batch_is_fewer_crossings_and_the_worker_runs_each_call_once(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK) as student:
        process = process_of(student)
        values = list(student.map("counted", [(i,) for i in range(300)]))
        assert values == list(range(1, 301))
        assert process._batches == 1
        assert student.how_many() == 300


def test_answers_are_bounded_per_call_and_arguments_split_over_frames(slot: GradingSlot) -> None:
    big = np.zeros(3_000_000)  # 24 MB: three of them do not fit one 64 MiB frame
    with running(slot, NOTEBOOK) as student:
        process = process_of(student)
        assert list(student.map("size", [(big,)] * 4)) == [big.size] * 4
        assert process._batches > 1 and process.restarts == 0
        verdicts = verdicts_of(student.map("f", [(1,), (11,), (2,)]), 3)
        # the 72 MB answer is that call's unreadable value; the worker goes on
        assert [kind for kind, _ in verdicts] == ["value", "UnsupportedValue", "value"]
        assert process.restarts == 0


def test_a_check_that_stops_early_loses_nothing_and_charges_nothing(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK, timeout=0.5) as student:
        process = process_of(student)
        results = student.map("f", [(1,), (2,), (7,), (4,)])
        assert next(results) == 1
        # a single call meanwhile: the batch's answers are read first (the time-out of
        # the call never reached stops the worker, and a new one answers)
        assert student.f(10) == 10
        assert process.timed_out == {}  # not charged: no check read that call yet
        # the check comes back to the batch: the kept answers, then the rest, in order
        rest = verdicts_of(results, 3)
        # (the last is refused as a single call would be: no larger than one that ran out)
        assert [kind for kind, _ in rest] == ["value", "CallTimeout", "NotRun"]
        assert "f" in process.timed_out  # charged now that a check read it
        with pytest.raises(StopIteration):
            next(results)


def test_a_worker_stopped_by_a_call_no_check_read_costs_no_restart_until_read(
        slot: GradingSlot, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(student_process, "MAX_CALL_RESTARTS", 1)
    with running(slot, NOTEBOOK, timeout=0.5) as student:
        process = process_of(student)
        batches = []
        for _ in range(2):  # two checks that stop reading before the call that spins
            batches.append(student.map("f", [(1,), (7,)]))
            assert next(batches[-1]) == 1
            # the spinning call is drained before this one: it stops the worker, unread
            assert student.f(10) == 10
        assert process.restarts == 2 and process.unread_stops == 2
        # read now: the time-outs count against the function, and their restarts too
        for results in batches:
            assert [kind for kind, _ in verdicts_of(results, 1)] == ["CallTimeout"]
        assert process.unread_stops == 0
        with pytest.raises(CallTimeout):
            student.burn(2)  # stops the worker once more: now over the limit of one
        with pytest.raises(WorkerCrashed, match="stopped earlier"):
            student.how_many()


def test_the_budget_ends_a_batch_as_it_ends_single_calls(slot: GradingSlot) -> None:
    def verdicts(batched: bool) -> list[str]:
        session = StudentProcess(slot=slot, cells=[(0, NOTEBOOK)], data_files=[],
                                 policy=IsolationPolicy(), notebook_timeout=60, cpu_budget=60)
        try:
            report = session.start()
            session.cpu_budget = session.cpu_seconds + 0.5
            student = Student(session, timeout=5, functions=report.functions, forbidden={},
                              log=CallLog())
            items = [(0.3,), (0.3,), (0.01, 0), (0.01,)]
            found = (verdicts_of(student.map("burn", items), 4) if batched
                     else one_by_one(student, "burn", items))
        finally:
            session.close()
        return [kind for kind, _ in found]

    assert verdicts(batched=True) == verdicts(batched=False) == [
        "value", "CallTimeout", "NotRun", "NotRun"]


def test_items_holding_functions_are_called_one_by_one(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK) as student:
        assert list(student.map("apply", [(np.sin, 0.0), (lambda x: 2 * x, 3.0)])) == [1.0, 7.0]


def test_an_item_that_is_not_a_tuple_of_arguments_is_the_checks_error(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK) as student:
        with pytest.raises(UsageError, match="tuple of one call's arguments"):
            student.map("f", [1, 2])


def test_forged_answers_from_inside_a_call_are_a_violation(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK) as student:
        process = process_of(student)
        number = process._batches + 1
        verdicts = verdicts_of(student.map("forge", [(number,), (2,), (3,)]), 3)
        assert verdicts[-1][0] == "ProtocolViolation", verdicts
        assert process.report is not None and "broke the grader's protocol" in process.report.violation


def test_a_forked_child_never_answers_for_its_parent(slot: GradingSlot) -> None:
    with running(slot, NOTEBOOK) as student:
        assert list(student.map("fork_and_answer", [(1,), (2,)])) == [1, 2]
        assert student.f(5 - 4) == 1  # still in step


# -- a peer written here -------------------------------------------------------------------
def item(batch: int, i: int, value: Any = 1) -> dict[str, Any]:
    return {"op": "item", "batch": batch, "i": i, "ok": True, "value": value, "stdout": ""}


@pytest.fixture
def short_backstop(monkeypatch: pytest.MonkeyPatch) -> None:
    """Waits end after about a second, not the 15 s a loaded machine needs."""
    monkeypatch.setattr(student_process, "WALL_SLACK", 1.0)


def peer_session(sock: socket.socket) -> Student:
    process = StudentProcess(slot=None, cells=[], data_files=[], policy=IsolationPolicy(),  # type: ignore[arg-type]
                             notebook_timeout=1.0, cpu_budget=100.0)
    process._sock, process._clock = sock, IdleClock()  # type: ignore[assignment]
    process.report = NotebookRun(cells=(), stdout="", functions=("f",), seconds=0.0,
                                 crashed=True)  # no restart: the peer is the only worker
    process._started_at = time.monotonic()
    return Student(process, timeout=0.2, functions=("f",), forbidden={}, log=CallLog())


def against(peer: Any, count: int = 3) -> list[Verdict]:
    """The verdicts of ``student.map("f", [(0,), ...])`` against ``peer(sock, stop)``;
    fails the test if the grader is still waiting after a minute.

    The peer's end is the peer's to close: closed here, under a peer still writing, its
    descriptor number could meanwhile belong to another file. ``stop`` is set once the
    grader is done with it.
    """
    ours, theirs = socket.socketpair()
    box: dict[str, Any] = {}
    stop = threading.Event()
    peer_thread = threading.Thread(target=peer, args=(theirs, stop), daemon=True)
    with ours:
        student = peer_session(ours)
        peer_thread.start()

        def grade() -> None:
            try:
                box["verdicts"] = verdicts_of(student.map("f", [(k,) for k in range(count)]),
                                              count)
            except BaseException as exc:  # handed to the test
                box["error"] = exc

        thread = threading.Thread(target=grade, daemon=True)
        thread.start()
        thread.join(60)
        assert not thread.is_alive(), "the grader hung on a peer that lies"
    stop.set()
    peer_thread.join(30)
    assert "error" not in box, box["error"]
    return box["verdicts"]


def honest_then(tail: list[Any]) -> Any:
    """A peer that reads the batch, then writes ``tail`` (frames, or raw bytes)."""
    def peer(sock: socket.socket, stop: threading.Event) -> None:
        with sock:
            try:
                request = frames.recv_message(sock)
                batch = request["batch"]  # type: ignore[index]
                for value in tail:
                    data = value(batch) if callable(value) else value
                    sock.sendall(data if isinstance(data, bytes) else frame(data))
            except (OSError, EOFError):  # the grader closed its end: done with this peer
                return
            stop.wait(30)  # silent, the socket open, until the grader is done
    return peer


@pytest.mark.parametrize("tail, violation_at", [
    ([lambda b: item(b + 1, 0)], 0),                                     # another batch
    ([lambda b: item(b, 1), lambda b: item(b, 0)], 0),                   # out of order
    ([lambda b: item(b, 0), lambda b: item(b, 0)], 1),                   # a second answer
    ([lambda b: item(b, 0), lambda b: {"op": "callback", "id": "g1", "args": [], "kwargs": {}}],
     1),                                                                 # a request
    ([lambda b: item(b, 0), lambda b: item(b, 1), lambda b: item(b, 2), lambda b: item(b, 2)],
     2),                                                                 # one answer too many
    ([lambda b: item(b, 0), lambda b: {"ok": True, "value": 1}], 1),     # an untagged answer
    (["not a dict"], 0),
], ids=["other-batch", "out-of-order", "duplicate", "callback", "extra", "untagged", "junk"])
def test_an_answer_the_batch_did_not_ask_for_is_a_violation(tail: list[Any], violation_at: int,
                                                            short_backstop: None) -> None:
    verdicts = against(honest_then(tail))
    assert all(kind == "value" for kind, _ in verdicts[:violation_at]), verdicts
    assert verdicts[violation_at][0] == "ProtocolViolation", verdicts
    assert "broke the grader's protocol" in verdicts[violation_at][1]
    # the worker is gone: the calls after it are not run, and say why
    assert all(kind == "ProtocolViolation" for kind, _ in verdicts[violation_at + 1:]), verdicts


def test_a_peer_that_stops_writing_is_stopped_at_the_backstop(short_backstop: None) -> None:
    start = time.monotonic()
    verdicts = against(honest_then([lambda b: item(b, 0)]))
    assert verdicts[0][0] == "value" and verdicts[1][0] == "CallTimeout", verdicts
    assert "it was waiting" in verdicts[1][1]
    assert time.monotonic() - start < 30


def test_an_answer_that_never_ends_the_batch_is_stopped_at_the_backstop(short_backstop: None) -> None:
    verdicts = against(honest_then([lambda b: item(b, 0), lambda b: item(b, 1),
                                    lambda b: item(b, 2)]))
    assert [kind for kind, _ in verdicts] == ["value", "value", "CallTimeout"], verdicts


def test_an_oversized_answer_is_refused_before_it_is_read(short_backstop: None) -> None:
    header = b'{"v":1,"bufs":[%d]}' % MAX_FRAME_BYTES
    verdicts = against(honest_then([lambda b: item(b, 0), struct.pack(">I", len(header)) + header]))
    assert verdicts[0][0] == "value" and verdicts[1][0] in {"UnsupportedValue"}, verdicts


def test_a_peer_that_never_reads_the_batch_is_stopped_at_the_backstop(short_backstop: None) -> None:
    """Three 16 MB arguments fill the socket; the send waits only until the backstop."""
    ours, theirs = socket.socketpair()
    box: dict[str, Any] = {}
    with ours, theirs:
        student = peer_session(ours)
        big = np.zeros(2_000_000)

        def grade() -> None:
            box["verdicts"] = verdicts_of(student.map("f", [(big,)] * 3), 3)

        thread = threading.Thread(target=grade, daemon=True)
        thread.start()
        thread.join(60)
        assert not thread.is_alive(), "the grader blocked on a peer that never reads"
    assert box["verdicts"][0][0] == "CallTimeout", box


def test_a_batch_that_sends_nothing_useful_costs_no_engine_error(short_backstop: None) -> None:
    """Every kind of verdict is the student's: nothing the peer does raises anything else."""
    for tail in ([b"\x00\x00\x00\x05{{{{{"], [lambda b: {"op": "map-done", "batch": b, "count": 3}]):
        verdicts = against(honest_then(tail))
        assert verdicts[0][0] in {"ProtocolViolation", "UnsupportedValue"}, verdicts
        assert all(kind in {"ProtocolViolation", "UnsupportedValue", "WorkerCrashed"}
                   for kind, _ in verdicts), verdicts
