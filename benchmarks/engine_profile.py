"""Where one submission's time goes: grade hull submissions with one Grader and time each phase.

Usage: ``python benchmarks/engine_profile.py [--count 24] [--before REF]
[--trivial | --released [--floor]] [--json PATH]``.

Grades ``count`` submissions (the hull assignment's examples, in turn, or with
``--trivial`` the one-cell, one-check assignment of ``engine_vs_peers.py``) with one
:class:`autograder.engine.grader.Grader`, after one warm-up submission that starts the
warm worker and is not counted, and times each phase of every submission:

* static scan: ``staticscan.scan`` of the cells (grader);
* worker start/sandbox: from the request for a child until its "started" message
  (grader, the warm parent's ``fork`` and the child entering the sandbox), less the
  static scan, which runs meanwhile once the slot is warm (the child is forked ahead
  of it, ``StudentProcess.launch``);
* notebook run: from "started" to "ready" (the child running the cells);
* pytest session and collection: the check run outside the check items. The
  grader keeps one pytest session (:class:`autograder.engine.checkrun.CheckSuite`),
  configured and collected in the warm-up submission, so this is what each run
  adds around the items (module globals put back, the plugin pointed at the
  submission, sys.path and sys.modules set and cleared); before that session, it
  was a whole ``pytest.main`` per submission (configuration, plugins, importing
  and collecting the checks);
* checks: the check items, with the child's time answering their calls;
* sweep: killing the child and sweeping the slot (:func:`autograder.sandbox.reaper.kill_child`
  and :func:`~autograder.sandbox.reaper.sweep_slot`), most of whose wall time is the
  killed child's own exit;
* child exit, reaping: the worker side's CPU that no phase sees (the child after its
  last answer, its exit and the freeing of its memory, and the warm parent's work
  besides its forks), from the warm parent's own and reaped children's CPU over the
  whole run less what the phases counted, spread evenly over the submissions;
* other: the rest of ``Grader.grade`` (reading the notebook, results).

For each phase it prints the median wall and CPU milliseconds per submission and
the phase's share of all CPU (from the means; grader, warm parent and child
together). With ``--released --floor`` it also runs the bare floor of
``engine_vs_peers.py`` (``_floor.py``) on the same notebooks in the same order, after
one unmeasured round of them, once before the engine and once after, and sets each
phase beside what the floor spends on it (means per submission): the notebook run
beside the floor's cells, the checks beside its check items, every other phase beside
nothing; so the engine's overhead over the floor is split by phase. With ``--before
REF`` (such as 5fc7bef, the commit before the sweep and scan changes, whose modules
the engine of that time can still import) it also runs the old code of ``REF`` in
the same run: the old scan on
every submission's cells beside the new one (and checks both report the same),
and the old sweep on every other submission, and prints the ratios old / new.
CPU of the child and the warm parent is read from ``/proc/<pid>/schedstat``
(nanoseconds, summed over its threads; ``/proc/<pid>/stat`` counts 10 ms clock ticks, which put a trivial
child's few milliseconds at 0), when the grader reads the child's messages; a child
that ran its cells before the grader read "started" has its notebook run counted
in "worker start/sandbox". Figures move with the load of
the machine, the ratios (taken in one run) less. Not a test: nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
import types
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout, whatever is installed

import pytest  # noqa: E402
from _record import Figure, add_json_option, record  # noqa: E402

from autograder.engine import checkrun  # noqa: E402

from autograder.engine import grader  # noqa: E402

from autograder.engine import student_process  # noqa: E402

from autograder.engine import staticscan  # noqa: E402
from autograder.engine.assignment import load_assignment  # noqa: E402
from autograder.sandbox.cputime import process_cpu_seconds as _stat_cpu_seconds  # noqa: E402

HULL = ROOT / "assignments" / "hull"
#: the worker side's CPU the phases do not see: the child after its last answer (its exit,
#: the kernel tearing down its memory) and the warm parent's reaping, from the warm
#: parent's own and reaped-children time over the run, less what the phases counted
UNSEEN = "child exit, reaping"
PHASES = ("static scan", "worker start/sandbox", "notebook run", "pytest session/collection",
          "checks", "sweep", UNSEEN, "other")


class Probe:
    """Wall seconds, grader CPU seconds and worker CPU seconds per phase of one submission."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = defaultdict(float)
        self.cpu: dict[str, float] = defaultdict(float)  # this process (the grader)
        self.worker: dict[str, float] = defaultdict(float)  # the warm parent and the child
        self.child: dict[str, float] = {}  # the child's CPU clock at "started" and "ready"
        self.spawned: tuple[float, float, float] | None = None

    def add(self, phase: str, wall: float, cpu: float, worker: float = 0.0) -> None:
        self.wall[phase] += wall
        self.cpu[phase] += cpu
        self.worker[phase] += worker

    def total_cpu(self, phase: str) -> float:
        return self.cpu[phase] + self.worker[phase]


def timed(probe: Callable[[], Probe], phase: str,
          function: Callable[..., Any]) -> Callable[..., Any]:
    """``function``, charging its wall and grader CPU time to ``phase``."""
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        wall, cpu = time.perf_counter(), time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            probe().add(phase, time.perf_counter() - wall, time.process_time() - cpu)
    return wrapper


class PytestTimer:
    """Times collection and the check items of the inner pytest run."""

    def __init__(self, probe: Callable[[], Probe]) -> None:
        self.probe = probe

    @pytest.hookimpl(hookwrapper=True)
    def pytest_collection(self, session: pytest.Session) -> Any:
        wall, cpu = time.perf_counter(), time.process_time()
        yield
        self.probe().add("collection", time.perf_counter() - wall, time.process_time() - cpu)

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(self, item: pytest.Item, nextitem: pytest.Item | None) -> Any:
        wall, cpu = time.perf_counter(), time.process_time()
        yield
        self.probe().add("checks", time.perf_counter() - wall, time.process_time() - cpu)


def load_before(ref: str) -> dict[str, types.ModuleType] | None:
    """The modules cgroups, session and staticscan as they were at ``ref``; None if git
    cannot show them (not a git checkout, or ``ref`` unknown)."""
    modules: dict[str, types.ModuleType] = {}
    for name in ("cgroups", "staticscan", "session"):
        shown = subprocess.run(["git", "-C", str(ROOT), "show", f"{ref}:autograder/{name}.py"],
                               capture_output=True, text=True)
        if shown.returncode != 0:
            print(f"(no old code path: git show {ref}:autograder/{name}.py failed: "
                  f"{shown.stderr.strip()[:200]})")
            return None
        module = types.ModuleType(f"before_{name}")
        sys.modules[module.__name__] = module  # dataclasses look their module up
        try:
            exec(compile(shown.stdout, f"{ref}:autograder/{name}.py", "exec"), module.__dict__)
        except ImportError as exc:  # it imports modules the engine has since moved
            print(f"(no old code path: {ref}:autograder/{name}.py cannot be loaded beside "
                  f"this engine: {exc})")
            return None
        modules[name] = module
    modules["session"].cgroups = modules["cgroups"]
    return modules


def instrument(current: Callable[[], Probe], before: dict[str, types.ModuleType] | None,
               old_sweep: Callable[[], bool], scan_pairs: list[tuple[float, float, bool]]) -> None:
    """Wrap the engine's phases (in this process only) so that they report to ``current()``."""
    new_scan = staticscan.scan

    def old_scan(sources: Any, forbid: Any) -> tuple[Any, float]:
        wall = time.perf_counter()
        assert before is not None
        return before["staticscan"].scan(sources, forbid), time.perf_counter() - wall

    def scan(sources: Any, forbid: Any) -> Any:
        # The old scan (outside the phase's figures) runs first on every other
        # submission, so that neither gets the other's warm caches every time.
        first = before is not None and len(scan_pairs) % 2 == 0
        if first:
            old, old_wall = old_scan(sources, forbid)
        wall, cpu = time.perf_counter(), time.process_time()
        report = new_scan(sources, forbid)
        new_wall, spent = time.perf_counter() - wall, time.process_time() - cpu
        probe = current()
        if probe.spawned is not None:  # the child, forked ahead, is entering its sandbox:
            # the scan is its own phase, not part of the wait for "started"
            start_wall, start_cpu, fork = probe.spawned
            probe.spawned = (start_wall + new_wall, start_cpu + spent, fork)
        probe.add("static scan", new_wall, spent)
        if before is not None:
            if not first:
                old, old_wall = old_scan(sources, forbid)
            scan_pairs.append((old_wall, new_wall, repr(old) == repr(report)))
        return report
    staticscan.scan = scan

    spawn, wait = student_process.StudentProcess._spawn, student_process.StudentProcess._await

    def spawn_child(self: student_process.StudentProcess) -> None:
        warm = self.slot.warm_parent
        warm_before = process_cpu_seconds(warm) if warm else 0.0
        wall, cpu = time.perf_counter(), time.process_time()
        spawn(self)
        fork = process_cpu_seconds(self.slot.warm_parent or 0) - warm_before  # its fork()
        current().spawned = (wall, cpu, max(0.0, fork))

    def await_message(self: student_process.StudentProcess, *args: Any) -> Any:
        message = wait(self, *args)
        op = message.get("op") if isinstance(message, dict) else None
        probe = current()
        if op in ("started", "ready") and self._pid is not None:
            probe.child[op] = process_cpu_seconds(self._pid, below=True)
        if op == "started" and probe.spawned is not None:
            wall, cpu, fork = probe.spawned
            probe.add("worker start/sandbox", time.perf_counter() - wall,
                      time.process_time() - cpu, fork + probe.child["started"])
            probe.spawned, probe.child["mark"] = None, time.perf_counter()
        elif op == "ready" and "mark" in probe.child:
            probe.add("notebook run", time.perf_counter() - probe.child.pop("mark"), 0.0,
                      probe.child["ready"] - probe.child.get("started", 0.0))
        return message
    student_process.StudentProcess._spawn = spawn_child
    student_process.StudentProcess._await = await_message

    kill_child, sweep_slot = student_process.kill_child, student_process.sweep_slot

    def kill(pid: int, pidfd: int | None) -> None:
        if before is not None and old_sweep():
            before["session"].kill_group(pid)
        else:
            kill_child(pid, pidfd)
    timed_kill = timed(current, "sweep", kill)

    def read_then_kill(pid: int, pidfd: int | None) -> None:
        probe = current()
        if "ready" in probe.child:  # the child's time answering the checks' calls
            probe.worker["checks"] += max(0.0, process_cpu_seconds(pid, below=True) - probe.child.pop("ready"))
        timed_kill(pid, pidfd)

    def sweep(policy: Any, slot: int, warm_parent: int | None, child: Any = None) -> None:
        if before is not None and old_sweep():
            before["session"].sweep_slot(policy, slot, warm_parent)
        else:
            sweep_slot(policy, slot, warm_parent, child)
    student_process.kill_child = read_then_kill
    student_process.sweep_slot = timed(current, "sweep", sweep)

    prepare = checkrun._prepareconfig

    def prepareconfig(args: Any, plugins: Any = None) -> Any:
        return prepare(args, plugins=[*(plugins or []), PytestTimer(current)])
    checkrun._prepareconfig = prepareconfig
    grader.CheckSuite.run = timed(current, "pytest", grader.CheckSuite.run)


def process_cpu_seconds(pid: int, *, below: bool = False, _depth: int = 0) -> float:
    """CPU seconds of the process ``pid`` (with ``below``, and of the processes below it
    that still run): the sum of their threads' ``schedstat``; from ``/proc/<pid>/stat``
    where those files are missing; 0.0 when it is gone.

    A submission's child is read with ``below``: with a PID namespace (as root), the
    child the grader forked is a relay and the student's code runs in its child
    (:mod:`autograder.sandbox.pidns`).
    """
    try:
        total = 0
        children: list[int] = []
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/schedstat", "rb") as handle:
                total += int(handle.read().split()[0])
            if below and _depth < 3:
                with open(f"/proc/{pid}/task/{task}/children", "rb") as handle:
                    children += [int(c) for c in handle.read().split()]
        return total / 1e9 + sum(process_cpu_seconds(c, below=True, _depth=_depth + 1)
                                 for c in children)
    except (OSError, ValueError, IndexError):
        return _stat_cpu_seconds(pid)


def median_ms(values: list[float]) -> float:
    return 1000 * statistics.median(values) if values else 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=24, help="submissions to time (default 24)")
    parser.add_argument("--before", default=None,
                        help="git revision whose scan and sweep to compare with (default: "
                        "none, this code only)")
    parser.add_argument("--no-before", action="store_true",
                        help="time this code only (the default; kept for old command lines)")
    parser.add_argument("--trivial", action="store_true",
                        help="profile the one-cell, one-check assignment of engine_vs_peers.py "
                        "instead of hull (the engine's own overhead)")
    parser.add_argument("--released", action="store_true",
                        help="hull submissions written into the released notebook (every cell "
                        "of it, its test cells too), as engine_vs_peers.py grades them, instead "
                        "of the three-cell examples")
    parser.add_argument("--floor", action="store_true",
                        help="with --released: the bare floor on the same notebooks, phase by "
                        "phase beside the engine")
    add_json_option(parser, "engine_profile")
    options = parser.parse_args()
    if options.floor and not options.released:
        parser.error("--floor goes with --released (the notebooks engine_vs_peers.py grades)")

    before = None if options.no_before or not options.before else load_before(options.before)
    probes: list[Probe] = [Probe()]
    scan_pairs: list[tuple[float, float, bool]] = []
    old_sweep = lambda: len(probes) % 2 == 0  # noqa: E731 - every other submission
    instrument(lambda: probes[-1], before, old_sweep, scan_pairs)

    with tempfile.TemporaryDirectory(prefix="bench-profile-") as tmp:
        if options.trivial:
            from engine_vs_peers import write_trivial
            folder, batch = write_trivial(Path(tmp), 2)
            examples = sorted(batch.glob("*.ipynb"))
        elif options.released:
            from grade_vs_nbgrader import build_batch
            folder, examples = HULL, build_batch(Path(tmp) / "submitted", 6)
        else:
            folder, examples = HULL, sorted((HULL / "examples").glob("*.ipynb"))
        # The floor runs before and after the engine and both count: a machine whose speed
        # drifts during the run moves both sides alike.
        floors = [run_floor(folder, examples, options.count)] if options.floor else []
        rows = profile(folder, examples, options.count, probes, old_sweep, scan_pairs)
        floors += [run_floor(folder, examples, options.count)] if options.floor else []
        floor = {key: [v for f in floors for v in f[key]] for key in ("cells_cpu", "checks_cpu")
                 } if floors else None
    name = ("trivial assignment" if options.trivial else
            "hull, released notebooks" if options.released else "hull")
    figures = report(rows, scan_pairs, before is not None, options.before, name)
    if floor is not None:
        figures += beside_floor(rows, floor, before is not None)
    record("engine_profile", figures, path=options.json,
           notes=f"{name}: {options.count} submissions timed with one Grader after one warm-up; "
           "medians per submission (the CPU total and shares from means); CPU = grader + "
           "warm parent + child.")


def profile(folder: Path, examples: list[Path], count: int, probes: list[Probe],
            old_sweep: Callable[[], bool], scan_pairs: list[tuple[float, float, bool]],
            ) -> list[tuple[Probe, bool, float, float]]:
    """Grade ``count`` of ``examples`` in turn with one grader, after one warm-up submission."""
    rows: list[tuple[Probe, bool, float, float]] = []
    with grader.Grader(load_assignment(folder)) as graded_by:
        graded_by.grade(examples[0])  # warm-up: starts the worker
        scan_pairs.clear()
        time.sleep(0.2)  # the warm-up's child reaped before the count starts
        warm = graded_by._slot.warm_parent  # internal: the slot whose children are timed
        worker_before = _stat_cpu_seconds(warm) if warm else 0.0
        for index in range(count):
            probes.append(Probe())
            wall, cpu = time.perf_counter(), time.process_time()
            graded_by.grade(examples[index % len(examples)])
            rows.append((probes[-1], old_sweep(), time.perf_counter() - wall,
                         time.process_time() - cpu))
        time.sleep(0.2)  # the warm parent reaps the last child on SIGCHLD
        if warm and graded_by._slot.warm_parent == warm:
            seen = sum(sum(p.worker.values()) for p, *_ in rows)
            unseen = (_stat_cpu_seconds(warm) - worker_before - seen) / count
            for probe, *_ in rows:  # spread evenly: /proc/<pid>/stat counts 10 ms ticks
                probe.worker[UNSEEN] = unseen
    return rows


def report(rows: list[tuple[Probe, bool, float, float]],
           scan_pairs: list[tuple[float, float, bool]], compared: bool, ref: str,
           name: str) -> list[Figure]:
    """Print the breakdown (and with ``compared`` the old code's ratios); return its figures."""
    # With --before the old sweep ran on every other submission: the breakdown uses the others.
    current = [row for row in rows if not (compared and row[1])] or rows
    for probe, _, wall, cpu in current:
        # The check items run inside the pytest session: the session is what is left.
        probe.add("pytest session/collection", probe.wall.pop("pytest") - probe.wall["checks"],
                  probe.cpu.pop("pytest") - probe.cpu["checks"])
        probe.add("other", max(0.0, wall - sum(probe.wall[p] for p in PHASES[:-1])),
                  max(0.0, cpu - sum(probe.cpu[p] for p in PHASES[:-1])))
    means = {p: statistics.fmean(pr.total_cpu(p) for pr, *_ in current) for p in PHASES}
    total = sum(means.values()) or 1.0
    print(f"{name}, {len(rows)} submissions timed ({len(current)} in the breakdown), one Grader, "
          "after one warm-up submission; CPU = grader + warm parent + child")
    print(f"{'phase':28} {'wall ms':>9} {'CPU ms':>9} {'grader':>8} {'worker':>8} "
          f"{'CPU share':>10}")
    figures = []
    for phase in PHASES:
        columns = (("wall", median_ms([p.wall[phase] for p, *_ in current]), "ms"),
                   ("CPU", median_ms([p.total_cpu(phase) for p, *_ in current]), "ms"),
                   ("grader CPU", median_ms([p.cpu[phase] for p, *_ in current]), "ms"),
                   ("worker CPU", median_ms([p.worker[phase] for p, *_ in current]), "ms"),
                   ("CPU share", 100 * means[phase] / total, "%"))
        print(f"{phase:28} {columns[0][1]:9.1f} {columns[1][1]:9.1f} {columns[2][1]:8.1f} "
              f"{columns[3][1]:8.1f} {columns[4][1]:9.1f}%")
        figures += [Figure(f"{phase}: {label}", value, unit) for label, value, unit in columns]
    print(f"{'whole submission':28} {median_ms([w for _, _, w, _ in current]):9.1f} "
          f"{1000 * total:9.1f}"
          "   (medians per submission; the CPU total and shares are from means)")
    print("  of which collection (inside the pytest session): "
          f"{median_ms([p.wall['collection'] for p, *_ in current]):.1f} ms wall")
    grader_ms = median_ms([c for *_, c in current])
    print(f"grader process CPU per submission: {grader_ms:.1f} ms "
          "(median; every phase's grader column and the rest of Grader.grade)")
    figures += [Figure("whole submission: wall (median)",
                       median_ms([w for _, _, w, _ in current]), "ms"),
                Figure("whole submission: CPU (mean)", 1000 * total, "ms"),
                Figure("grader process CPU per submission", grader_ms, "ms")]
    if not compared:
        return figures
    old = [p for p, is_old, *_ in rows if is_old]
    new = [p for p, is_old, *_ in rows if not is_old]
    print(f"\nbefore ({ref}) / after, in this run (medians per submission):")
    for label, pick in (("sweep wall", lambda p: p.wall["sweep"]),
                        ("sweep CPU", lambda p: p.cpu["sweep"])):
        o, n = median_ms([pick(p) for p in old]), median_ms([pick(p) for p in new])
        print(f"  {label:11} before {o:8.2f} ms  after {n:8.2f} ms  ratio {_ratio(o, n)}"
              f"  ({len(old)} / {len(new)} submissions)")
    o, n = median_ms([a for a, _, _ in scan_pairs]), median_ms([b for _, b, _ in scan_pairs])
    same = sum(s for _, _, s in scan_pairs)
    print(f"  {'scan wall':11} before {o:8.2f} ms  after {n:8.2f} ms  ratio {_ratio(o, n)}"
          f"  (same report on {same} of {len(scan_pairs)} submissions)")
    return figures


def run_floor(folder: Path, examples: list[Path], count: int) -> dict[str, Any]:
    """The bare floor over the notebooks :func:`profile` graded, in its order, after one
    unmeasured round of ``examples`` (as the engine's warm-up and warm parent)."""
    from engine_vs_peers import floor_reports

    order = [examples[index % len(examples)] for index in range(count)]
    return floor_reports(folder, [examples + order], warm=len(examples))[0]


def beside_floor(rows: list[tuple[Probe, bool, float, float]], floor: dict[str, Any],
                 compared: bool) -> list[Figure]:
    """Each phase's mean CPU per submission beside the floor's; the overhead split by phase."""
    current = [row for row in rows if not (compared and row[1])] or rows
    engine = {p: 1000 * statistics.fmean(pr.total_cpu(p) for pr, *_ in current) for p in PHASES}
    theirs = {"notebook run": 1000 * statistics.fmean(floor["cells_cpu"]),
              "checks": 1000 * statistics.fmean(floor["checks_cpu"])}
    print("\nbeside the bare floor (_floor.py, the same notebooks; means of CPU ms per "
          "submission):")
    print(f"{'phase':28} {'engine':>9} {'floor':>9} {'overhead':>9} {'share':>7}")
    overhead = sum(engine.values()) - sum(theirs.values())
    figures = []
    for phase in PHASES:
        mine, base = engine[phase], theirs.get(phase, 0.0)
        share = 100 * (mine - base) / overhead if overhead else 0.0
        print(f"{phase:28} {mine:9.1f} {base:9.1f} {mine - base:9.1f} {share:6.1f}%")
        figures += [Figure(f"beside the floor: {phase}: engine CPU", mine, "ms",
                           "bare floor" if base else None, base if base else None),
                    Figure(f"beside the floor: {phase}: overhead", mine - base, "ms CPU"),
                    Figure(f"beside the floor: {phase}: share of the overhead", share, "%")]
    whole, base = sum(engine.values()), sum(theirs.values())
    print(f"{'whole submission':28} {whole:9.1f} {base:9.1f} {overhead:9.1f}   "
          f"({whole / base:.2f}x the floor)")
    figures.append(Figure("beside the floor: whole submission: engine CPU", whole, "ms",
                          "bare floor", base))
    return figures


def _ratio(before: float, after: float) -> str:
    return f"{before / after:6.1f}x" if after else "   n/a"


if __name__ == "__main__":
    main()
