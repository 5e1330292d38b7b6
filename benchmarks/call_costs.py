"""What one call of a student's function costs across the process boundary, and how many a
submission makes.

Usage: ``python benchmarks/call_costs.py [--calls 2000] [--repeat 3] [--batch 30] [--no-hull]``.

The checks call the student's functions in the sandboxed worker; each call is a
round trip (the arguments framed as JSON and raw array bytes, the answer framed
back, the child's CPU clock read around it). This prints, in one run, the CPU
microseconds per call on each side (grader + worker), for a few kinds of
arguments, with the slot on one core as the engine runs it (see
:mod:`autograder.sandbox.affinity`) and with ``AUTOGRADER_PIN_CORES=0``, against two
peers that run in this process:

* **direct**: the same function called directly (what the bare floor pays);
* **framed in process**: the same message and answer encoded and decoded with
  :mod:`autograder.boundary.codec`, without a second process (what the framing costs
  without the system calls, the wake-ups and the clock).

and the same calls made in batches of ``--batch`` with ``student.map`` (one request,
one answer frame per call: :mod:`autograder.engine.batch`), per call.

With the hull assignment (unless ``--no-hull``) it also grades its examples once
each with one :class:`~autograder.engine.grader.Grader` and counts the calls per
submission and the requests that carry them (a batch is one request), so the
boundary's share of a hull submission can be read off. CPU of the worker is the child's
as the engine's clock reads it (the slot's cgroup as root, else ``/proc``). Not a test: nothing
is asserted about speed.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout, whatever is installed

import numpy as np  # noqa: E402
from _record import Figure, add_json_option, record  # noqa: E402

from autograder.sandbox import affinity  # noqa: E402

from autograder.boundary import codec  # noqa: E402
from autograder.sandbox.cputime import CpuClock, slot_clock  # noqa: E402
from autograder.engine.proxy import CallLog, Student  # noqa: E402
from autograder.sandbox.policy import IsolationPolicy  # noqa: E402
from autograder.engine.slot import GradingSlot  # noqa: E402
from autograder.engine.student_process import StudentProcess  # noqa: E402

NOTEBOOK = '''
import numpy as np

def same(x):
    return x
'''

#: argument kinds: a scalar, a hull-sized point set, a large point set
ARGUMENTS: dict[str, Callable[[], Any]] = {
    "scalar": lambda: 0.5,
    "20 points (20x2 float)": lambda: np.random.default_rng(1).random((20, 2)),
    "2,000 points (2000x2 float)": lambda: np.random.default_rng(1).random((2000, 2)),
}


def same(x: Any) -> Any:
    return x


def framed(value: Any) -> Any:
    """The call's request and answer, encoded and decoded as the two processes do."""
    tree, buffers = codec.encode({"op": "call", "name": "same", "args": [value], "kwargs": {},
                                     "figures": False})
    request = codec.decode(tree, [bytearray(b) for b in buffers])
    assert isinstance(request, dict)
    tree, buffers = codec.encode({"ok": True, "value": same(*request["args"]), "stdout": ""})
    answer = codec.decode(tree, [bytearray(b) for b in buffers])
    assert isinstance(answer, dict)
    return answer["value"]


def per_call(calls: int, repeat: int, run: Callable[[], Any],
             child: CpuClock | None = None) -> tuple[float, float]:
    """Best (this process, child) CPU microseconds per call over ``repeat`` runs; the
    child's CPU from its clock as the engine reads it (the slot's cgroup as root)."""
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        cpu = time.process_time()
        if child is not None:
            child.start()
        for _ in range(calls):
            run()
        mine = (time.process_time() - cpu) / calls * 1e6
        theirs = child.used() / calls * 1e6 if child is not None else 0.0
        best = min(best, (mine, theirs), key=sum)
    return best


def measure(args: argparse.Namespace, pinned: bool) -> dict[str, tuple[float, float]]:
    """(grader, worker) CPU microseconds per call for each argument kind, with the slot
    on one core as the engine runs it, or with ``AUTOGRADER_PIN_CORES=0``."""
    os.environ[affinity.ENVIRONMENT_VARIABLE] = "1" if pinned else "0"
    found: dict[str, tuple[float, float]] = {}
    with GradingSlot() as slot, affinity.on_core(slot.core):
        session = StudentProcess(slot=slot, cells=[(0, NOTEBOOK)], data_files=[],
                                 policy=IsolationPolicy(), notebook_timeout=60)
        session.start()
        student = Student(session, timeout=120, functions=session.report.functions,
                          forbidden={}, log=CallLog())
        assert session._pid is not None
        # the child answering the calls, read by a clock of its own (the session's is
        # restarted by every call)
        child = slot_clock(session._pid, session.policy, slot.slot, slot.warm_parent)
        try:
            for label, make in ARGUMENTS.items():
                value = make()
                found[label] = per_call(args.calls, args.repeat, lambda: student.same(value),
                                        child)
                items = [(value,)] * args.batch
                grader, worker = per_call(max(1, args.calls // args.batch), args.repeat,
                                          lambda: list(student.map("same", items)), child)
                found[f"{label}, batched"] = (grader / args.batch, worker / args.batch)
        finally:
            session.close()
            child.close()
    return found


def boundary(args: argparse.Namespace) -> list[Figure]:
    """Print the table of CPU per call; return its figures."""
    setting = os.environ.get(affinity.ENVIRONMENT_VARIABLE)
    try:
        pinned, unpinned = measure(args, True), measure(args, False)
    finally:
        if setting is None:
            os.environ.pop(affinity.ENVIRONMENT_VARIABLE, None)
        else:
            os.environ[affinity.ENVIRONMENT_VARIABLE] = setting
    print(f"CPU microseconds per call (best of {args.repeat} runs of {args.calls:,} calls); "
          "grader + worker, the slot on one core (as the engine runs) and unpinned")
    print(f"{'argument':<28} {'direct':>7} {'framed':>7} {'one core':>17} {'unpinned':>17}"
          f" {'unpinned/one core':>18} {'one core/framed':>16}")
    figures = []
    for label, make in ARGUMENTS.items():
        value = make()
        direct, _ = per_call(args.calls, args.repeat, lambda: same(value))
        inproc, _ = per_call(args.calls, args.repeat, lambda: framed(value))
        (g1, w1), (g2, w2) = pinned[label], unpinned[label]
        (b1, v1), (b2, v2) = pinned[f"{label}, batched"], unpinned[f"{label}, batched"]
        print(f"{label:<28} {direct:>7.2f} {inproc:>7.1f}"
              f" {g1:>5.0f}+{w1:>5.0f}={g1 + w1:>5.0f} {g2:>5.0f}+{w2:>5.0f}={g2 + w2:>5.0f}"
              f" {(g2 + w2) / (g1 + w1):>17.2f}x {(g1 + w1) / inproc:>15.2f}x")
        print(f"{'  in batches of ' + str(args.batch):<28} {'':>7} {'':>7}"
              f" {b1:>5.0f}+{v1:>5.0f}={b1 + v1:>5.0f} {b2:>5.0f}+{v2:>5.0f}={b2 + v2:>5.0f}"
              f" {'':>18} {'':>16}   one by one / batched (one core): "
              f"{(g1 + w1) / (b1 + v1):.2f}x")
        figures += [Figure(f"{label}: direct", direct, "us CPU"),
                    Figure(f"{label}: framed in process", inproc, "us CPU"),
                    Figure(f"{label}: one core, grader + worker", g1 + w1, "us CPU",
                           "framed in process", inproc),
                    Figure(f"{label}: one core, grader", g1, "us CPU"),
                    Figure(f"{label}: one core, worker", w1, "us CPU"),
                    Figure(f"{label}: unpinned, grader + worker", g2 + w2, "us CPU",
                           "one core", g1 + w1),
                    Figure(f"{label}: unpinned, grader", g2, "us CPU"),
                    Figure(f"{label}: unpinned, worker", w2, "us CPU"),
                    Figure(f"{label}: one core, batched, grader + worker", b1 + v1, "us CPU",
                           "one core, one by one", g1 + w1),
                    Figure(f"{label}: unpinned, batched, grader + worker", b2 + v2, "us CPU",
                           "unpinned, one by one", g2 + w2)]
    return figures


def hull_calls() -> list[Figure]:
    """Calls per hull submission, and the requests that carry them (a batch is one)."""
    from autograder.engine.assignment import load_assignment
    from autograder.engine.grader import Grader, GradingOptions

    hull = ROOT / "assignments" / "hull"
    files = sorted((hull / "examples").glob("*.ipynb"))
    originals = {name: getattr(StudentProcess, name)
                 for name in ("call", "call_many", "request", "send_batch")}
    counts = {"calls": 0, "requests": 0}

    def counting(name: str) -> Any:
        def wrapper(self: StudentProcess, *a: Any, **k: Any) -> Any:
            if name == "call":
                counts["calls"] += 1
            elif name == "call_many":
                counts["calls"] += len(a[1])
            else:  # request (an ordinary call among them) or send_batch: one crossing
                counts["requests"] += 1
            return originals[name](self, *a, **k)
        return wrapper

    for name in originals:
        setattr(StudentProcess, name, counting(name))
    figures = []
    try:
        for public in (False, True):
            with Grader(load_assignment(hull), GradingOptions(public_only=public)) as grader:
                counts.update(calls=0, requests=0)
                for path in files:
                    grader.grade(path)
                label = "public checks" if public else "every check"
                calls, requests = counts["calls"] / len(files), counts["requests"] / len(files)
                print(f"hull, {label}: {calls:.1f} calls per submission in {requests:.1f} "
                      f"requests (over its {len(files)} examples)")
                figures += [Figure(f"hull, {label}: calls per submission", calls, "calls"),
                            Figure(f"hull, {label}: requests per submission", requests,
                                   "requests", "calls", calls)]
    finally:
        for name, original in originals.items():
            setattr(StudentProcess, name, original)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--batch", type=int, default=30, help="calls per student.map batch")
    parser.add_argument("--no-hull", action="store_true", help="skip counting hull's calls")
    add_json_option(parser, "call_costs")
    args = parser.parse_args()
    figures = boundary(args)
    if not args.no_hull:
        figures += hull_calls()
    record("call_costs", figures, path=args.json,
           notes=f"CPU microseconds per call, best of {args.repeat} runs of {args.calls:,} calls; "
           "grader + worker with the slot on one core (as the engine runs it) and unpinned "
           f"(AUTOGRADER_PIN_CORES=0); batched: student.map in batches of {args.batch}.")


if __name__ == "__main__":
    main()
