"""What a function passed to student code costs: callbacks against a direct call in the worker.

Usage: ``python benchmarks/callbacks.py [--repeat 3] [--scalars 10000]``.

Runs a tiny notebook in a real sandboxed worker and calls it through the
``student`` proxy, as checks do. Compares, in the same run:

* one student call that evaluates ``f`` once: ``f`` answered by the grader (a
  callback round trip) against ``f`` safe by name (``np.sin``, evaluated in the
  worker) and against a call that passes no function at all;
* one student call that evaluates ``f`` at ``--scalars`` scalars one by one:
  grader callbacks against the same safe function evaluated in the worker.

Prints wall-clock seconds (best of ``--repeat``), the CPU seconds charged to
the student (the worker's own; the grader's time inside callbacks is not
charged), and the ratios. Wall-clock figures depend on how busy the machine is.
"""

from __future__ import annotations

import argparse
import time
from typing import Any, Callable

import numpy as np
from _record import Figure, add_json_option, record

from autograder.engine.callbacks import traced
from autograder.engine.proxy import CallLog, Student
from autograder.engine.slot import GradingSlot
from autograder.engine.student_process import StudentProcess
from autograder.sandbox.policy import IsolationPolicy

NOTEBOOK = '''
def plain(x):
    return x

def once(f, x):
    return f(x)

def scalars(f, n):
    total = 0.0
    for i in range(n):
        total += f(i * 1e-3)
    return total
'''


def best(repeat: int, session: StudentProcess, run: Callable[[], Any]) -> tuple[float, float]:
    """(best wall seconds, CPU seconds charged to the worker in that run)."""
    results = []
    for _ in range(repeat):
        cpu = session.cpu_seconds
        start = time.perf_counter()
        run()
        results.append((time.perf_counter() - start, session.cpu_seconds - cpu))
    return min(results)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--scalars", type=int, default=10_000)
    parser.add_argument("--calls", type=int, default=200, help="calls timed for the one-call figures")
    add_json_option(parser, "callbacks")
    args = parser.parse_args()
    with GradingSlot() as slot:
        session = StudentProcess(slot=slot, cells=[(0, NOTEBOOK)], data_files=[],
                                 policy=IsolationPolicy(), notebook_timeout=60)
        session.start()
        student = Student(session, timeout=120, functions=session.report.functions,
                          forbidden={}, log=CallLog())
        try:
            figures = report(args, session, student)
        finally:
            session.close()
    record("callbacks", figures, path=args.json,
           notes=f"Best wall seconds of {args.repeat} runs; {args.calls} calls timed for the "
           "one-call figures. Student CPU is the worker's own (the grader's time inside "
           "callbacks is not charged to the student).")


def report(args: argparse.Namespace, session: StudentProcess, student: Student) -> list[Figure]:
    """Time the calls, print the table and the ratios; return them as figures."""
    k, n = args.calls, args.scalars
    remote, local = traced(np.sin), traced(np.sin, safe=True)
    rows = [
        ("call, no function", best(args.repeat, session,
                                   lambda: [student.plain(0.5) for _ in range(k)]), k),
        ("call, f in the worker (safe)", best(args.repeat, session,
                                              lambda: [student.once(local, 0.5) for _ in range(k)]), k),
        ("call, f by callback", best(args.repeat, session,
                                     lambda: [student.once(remote, 0.5) for _ in range(k)]), k),
        (f"{n:,} scalars, f in the worker", best(args.repeat, session,
                                                 lambda: student.scalars(local, n)), 1),
        (f"{n:,} scalars, f by callback", best(args.repeat, session,
                                               lambda: student.scalars(remote, n)), 1),
    ]
    print(f"{'what':<34} {'wall s':>10} {'student CPU s':>14}")
    for label, (wall, cpu), count in rows:
        print(f"{label:<34} {wall / count:>10.6f} {cpu / count:>14.6f}")
    (_, (plain, _), _), (_, (safe, _), _), (_, (callback, _), _) = rows[:3]
    (_, (loop_local, cpu_local), _), (_, (loop_remote, cpu_remote), _) = rows[3:]
    print()
    print(f"one callback round trip: {(callback - safe) / k * 1e3:.3f} ms "
          f"(call with a callback / call with a safe f = {callback / safe:.2f}x; "
          f"/ call without f = {callback / plain:.2f}x)")
    print(f"{n:,} scalar callbacks: {loop_remote:.3f} s against {loop_local:.3f} s evaluated in "
          f"the worker = {loop_remote / loop_local:.1f}x; per callback "
          f"{(loop_remote - loop_local) / n * 1e6:.0f} us wall, "
          f"{(cpu_remote - cpu_local) / n * 1e6:.0f} us of student CPU")
    assert remote.calls == args.repeat * (k + n) and local.calls == args.repeat * (k + n)
    figures = []
    for label, (wall, cpu), count in rows:
        figures += [Figure(f"{label}: wall", wall / count, "s"),
                    Figure(f"{label}: student CPU", cpu / count, "s")]
    return figures + [
        Figure("one callback round trip", (callback - safe) / k * 1e3, "ms wall"),
        Figure("call with a callback", callback / k, "s wall", "call with a safe f", safe / k),
        Figure("call with a callback", callback / k, "s wall", "call without f", plain / k),
        Figure(f"{n:,} scalars, f by callback", loop_remote, "s wall",
               "f evaluated in the worker", loop_local),
        Figure("per scalar callback", (loop_remote - loop_local) / n * 1e6, "us wall"),
        Figure("per scalar callback", (cpu_remote - cpu_local) / n * 1e6, "us student CPU"),
    ]


if __name__ == "__main__":
    main()
