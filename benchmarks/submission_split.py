"""Where one submission's CPU goes, by process, beside the bare floor in the same run.

Usage: ``python benchmarks/submission_split.py [--count 300] [--hull]``.

Grades ``count`` submissions with one :class:`autograder.engine.grader.Grader` (after 20
not counted), on the one-cell, one-check assignment of ``engine_vs_peers.py`` or,
with ``--hull``, on the hull examples with every check, and prints per submission:

* the grader's CPU (``time.process_time`` of this process: checks, results, sweep);
* the warm parent's own CPU (its ``/proc/<pid>/schedstat``, nanoseconds), mostly the
  ``fork`` that copies its page tables;
* the child's CPU at its "started" message (the fork's return and the sandbox's
  layers), at "ready" (the notebook's cells run), and just before it is killed
  (the calls the checks made), from the child's own ``schedstat`` (medians);
* the children's CPU with their exit, from the warm parent's ``cutime + cstime``
  (clock ticks, so only right on average over many submissions);

then the bare floor (``_floor.py``: the same cells and checks in one warm process)
on the same files, and the ratio of the engine's total to it. Not a test: nothing
is asserted. Figures move with the machine's load; the split moves less.
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _record import Figure, add_json_option, record  # noqa: E402
from engine_vs_peers import HULL, run_floor, write_trivial  # noqa: E402

from autograder.engine import student_process  # noqa: E402
from autograder.engine.assignment import load_assignment  # noqa: E402
from autograder.runners.local import grade_one  # noqa: E402
from autograder.engine.grader import Grader  # noqa: E402

TICK = os.sysconf("SC_CLK_TCK")


def runtime_ms(pid: int | None) -> float | None:
    """CPU ms the process ``pid`` ran so far (``schedstat``), or None once it is gone."""
    try:
        with open(f"/proc/{pid}/schedstat") as handle:
            return int(handle.read().split()[0]) / 1e6
    except (OSError, ValueError, IndexError, TypeError):
        return None


def reaped_children_ms(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    return (int(fields[13]) + int(fields[14])) / TICK * 1e3  # cutime + cstime


def record_child_marks(marks: dict[str, list[float]]) -> None:
    """Read the child's CPU at its "started" and "ready" messages and before its kill."""
    receive, kill = student_process.StudentProcess._await, student_process.StudentProcess._kill

    def on_message(self: Any, *args: Any, **kwargs: Any) -> Any:
        message = receive(self, *args, **kwargs)
        if isinstance(message, dict) and message.get("op") in ("started", "ready"):
            value = runtime_ms(self._pid)
            if value is not None:
                marks[message["op"]].append(value)
        return message

    def on_kill(self: Any) -> None:
        value = runtime_ms(self._pid) if self._pid is not None else None
        if value is not None:
            marks["kill"].append(value)
        kill(self)

    student_process.StudentProcess._await = on_message  # type: ignore[method-assign]
    student_process.StudentProcess._kill = on_kill  # type: ignore[method-assign]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=300)
    parser.add_argument("--hull", action="store_true", help="the hull examples, every check")
    add_json_option(parser, "submission_split")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="split-") as scratch:
        root = Path(scratch)
        if args.hull:
            assignment = HULL
            files = sorted((HULL / "examples").glob("*.ipynb"))
        else:
            assignment, batch = write_trivial(root, 20)
            files = sorted(batch.glob("*.ipynb"))
        notebooks = list(itertools.islice(itertools.cycle(files), args.count + 20))
        marks: dict[str, list[float]] = {"started": [], "ready": [], "kill": []}
        out = root / "out"
        with Grader(load_assignment(assignment)) as grader:
            grader.prepare()
            for k, path in enumerate(notebooks[:20]):
                grade_one(grader, path, f"warm{k}", out)
            parent = grader._slot.warm_parent
            assert parent is not None
            record_child_marks(marks)
            own, children = runtime_ms(parent) or 0.0, reaped_children_ms(parent)
            cpu, wall = time.process_time(), time.perf_counter()
            for k, path in enumerate(notebooks[20:]):
                grade_one(grader, path, f"s{k}", out)
            n = args.count
            grader_ms = (time.process_time() - cpu) / n * 1e3
            wall_ms = (time.perf_counter() - wall) / n * 1e3
            parent_ms = ((runtime_ms(parent) or 0.0) - own) / n
            children_ms = (reaped_children_ms(parent) - children) / n
        started, ready, before_kill = (statistics.median(marks[k]) for k in
                                       ("started", "ready", "kill"))
        floor = run_floor(assignment, notebooks[20:], False, procs=1)
    floor_ms = floor.cpu / n * 1e3
    total = grader_ms + parent_ms + children_ms
    name = "hull, every check" if args.hull else "trivial (one cell, one check)"
    print(f"{name}: {n} submissions on one grader, CPU ms per submission "
          f"(wall {wall_ms:.1f} ms per submission)")
    print(f"  grader                              {grader_ms:7.2f}")
    print(f"  warm parent (fork, request)         {parent_ms:7.2f}")
    print(f"  child, with its exit                {children_ms:7.2f}")
    print(f"    to 'started' (fork, sandbox)      {started:7.2f}")
    print(f"    cells, to 'ready'                 {ready - started:7.2f}")
    print(f"    calls, to the kill                {before_kill - ready:7.2f}")
    print(f"    exit and the rest (by difference) {children_ms - before_kill:7.2f}")
    print(f"  engine total                        {total:7.2f}")
    print(f"  bare floor (same files, one warm process) {floor_ms:.2f}")
    print(f"  ratio engine / floor: {total / floor_ms:.1f}x; "
          f"engine overhead {total - floor_ms:.2f} ms")
    record("submission_split", [
        Figure("wall per submission", wall_ms, "ms"),
        Figure("grader", grader_ms, "ms CPU"),
        Figure("warm parent (fork, request)", parent_ms, "ms CPU"),
        Figure("child, with its exit", children_ms, "ms CPU"),
        Figure("child: to 'started' (fork, sandbox)", started, "ms CPU"),
        Figure("child: cells, to 'ready'", ready - started, "ms CPU"),
        Figure("child: calls, to the kill", before_kill - ready, "ms CPU"),
        Figure("child: exit and the rest (by difference)", children_ms - before_kill, "ms CPU"),
        Figure("engine total", total, "ms CPU", "bare floor", floor_ms),
        Figure("engine overhead (total - floor)", total - floor_ms, "ms CPU"),
    ], path=args.json, notes=f"{name}: {n} submissions on one grader (after 20 not counted), "
       "CPU ms per submission; the child's marks are medians.")


if __name__ == "__main__":
    main()
