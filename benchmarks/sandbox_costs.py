"""What each part of the sandbox costs a child, beside a bare fork of the same parent.

Usage: ``python benchmarks/sandbox_costs.py [--count 200]``.

Forks ``count`` children from a parent that imported what the warm parent imports
(numpy, scipy, matplotlib, IPython) and prepared what it prepares before a fork (the
covered folders, the slot's cgroup, the seccomp filters, the shared Landlock ruleset,
``gc.freeze()``), and prints, in one run, the CPU milliseconds per child (its own
time and its exit, from ``RUSAGE_CHILDREN``) of

* a bare fork (the peer: the child exits at once);
* the whole sandbox (:func:`autograder.sandbox.confine.enter_sandbox` with the default
  policy), first with a network namespace made by each child, then as the worker
  runs it (one empty namespace made once by the parent, as root, and the child born
  as the first process of its own PID namespace), then with the relay process a
  child forks where its parent cannot make that namespace for it, then with one part
  turned off by policy at a time, so that each part's cost is the difference from
  the whole (without the network namespace, a child of that parent goes back to the
  host's);
* the whole sandbox and one IPython cell (what a trivial submission's child does
  before it answers the checks' calls),

with each line's ratio to the bare fork, and the machine's busy time per child from
``/proc/stat`` (it adds what the kernel does for the child outside it, such as
tearing a network namespace down). Run it as root for the figures of a grading
server (cgroup and user switch); as an ordinary user those parts are skipped by the
sandbox. Not a test: nothing is asserted; figures move with the machine's load.
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # this checkout, whatever is installed

import matplotlib  # noqa: E402  (the warm parent's imports, as autograder.worker makes them)

matplotlib.use("Agg")
import matplotlib.pyplot  # noqa: E402,F401
import numpy  # noqa: E402,F401
import scipy.interpolate  # noqa: E402,F401
import scipy.spatial  # noqa: E402,F401

from _record import Figure, add_json_option, record  # noqa: E402

from autograder.sandbox import confine, landlock, readable  # noqa: E402
from autograder.sandbox.policy import IsolationPolicy  # noqa: E402

from autograder.sandbox import seccomp  # noqa: E402
from autograder.worker import execute  # noqa: E402

CELL = "def double(x):\n    return 2 * x\n"


def _busy_ticks() -> int:
    """Non-idle clock ticks of the whole machine so far."""
    with open("/proc/stat") as handle:
        values = [int(v) for v in handle.readline().split()[1:]]
    return sum(values) - values[3] - values[4]  # minus idle and iowait


def children(count: int, work: Path, body: Callable[[Path], object],
             fork: Callable[[], int] = os.fork) -> tuple[float, float]:
    """CPU ms per child (its own, with its exit) and the machine's busy ms per child."""
    before, ticks = os.times(), _busy_ticks()
    for _ in range(count):
        workdir = Path(tempfile.mkdtemp(dir=work))
        pid = fork()
        if pid == 0:
            try:
                body(workdir)
            finally:
                os._exit(0)
        os.waitpid(pid, 0)
        try:
            os.rmdir(workdir)
        except OSError:  # the child wrote into it before its tmpfs was mounted: leave it
            pass
    after = os.times()
    time.sleep(0.5)  # the kernel's deferred work for the last children
    busy = (_busy_ticks() - ticks) * 1000 / os.sysconf("SC_CLK_TCK")
    own = (after.children_user + after.children_system
           - before.children_user - before.children_system)
    return 1000 * own / count, busy / count


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200, help="children per line (default 200)")
    add_json_option(parser, "sandbox_costs")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="sandbox-costs-") as scratch:
        figures = measure(args.count, Path(scratch))
    record("sandbox_costs", figures, path=args.json,
           notes=f"uid {os.geteuid()}; {args.count} children per line; CPU ms per child with "
           "its exit; busy: the whole machine's ms per child, counted until 0.5 s after the last.")
    return 0


def measure(count: int, root: Path) -> list[Figure]:
    """Print the table, with the children's folders in ``root``; return its figures."""
    os.chmod(root, 0o711)
    work = root / "work"
    work.mkdir(mode=0o711)
    os.chmod(work, 0o711)
    exclude = [ROOT]
    shell = execute.make_shell()
    execute.warm_up(shell)
    readable.prime_caches()
    seccomp.prepare_filters()
    whole = IsolationPolicy()
    print(f"load average {os.getloadavg()[0]:.2f}; uid {os.geteuid()}; {count} children "
          "per line; ms per child (busy: the whole machine's, counted until 0.5 s after the last)")
    print(f"  {'child':<36} {'CPU':>7} {'busy':>7} {'CPU ratio':>10}")
    gc.freeze()
    bare, busy = children(count, work, lambda _: None)
    print(f"  {'bare fork (peer)':<36} {bare:7.2f} {busy:7.2f} {1.0:9.1f}x", flush=True)
    figures = [Figure("bare fork (peer): CPU", bare, "ms"),
               Figure("bare fork (peer): busy", busy, "ms")]

    def line(label: str, policy: IsolationPolicy, *, with_cell: bool = False,
             relay: bool = False) -> None:
        probe = Path(tempfile.mkdtemp(dir=work))
        readable.coverable_folders(exclude, probe, policy)
        confine.prepare_cgroup(policy, 0)
        shared = landlock.shared_landlock(policy, work, exclude)
        os.rmdir(probe)

        def enter(workdir: Path) -> None:
            confine.enter_sandbox(policy, workdir, slot=0, exclude=exclude, shared=shared)

        def enter_and_run(workdir: Path) -> None:
            enter(workdir)
            execute.Execution(shell, execute.capture_output(1 << 20)).run(
                [(0, CELL)], lambda index: None)

        bodies = [(label, enter)]
        if with_cell:
            bodies.append(("whole sandbox and one IPython cell", enter_and_run))
        for name, body in bodies:
            # as the worker forks (confine.fork_child), or with the PID namespace's relay
            fork = os.fork if relay else lambda: confine.fork_child(policy)
            cpu, busy = children(count, work, body, fork)
            print(f"  {name:<36} {cpu:7.2f} {busy:7.2f} {cpu / bare:9.1f}x", flush=True)
            # an indented line is a variant of the whole sandbox
            shown = f"whole sandbox, {name.strip()}" if name.startswith(" ") else name
            figures.extend([Figure(f"{shown}: CPU", cpu, "ms", "bare fork", bare),
                            Figure(f"{shown}: busy", busy, "ms")])
        shared.close()

    # Before the parent moves into the slot's empty network namespace, each child makes its own.
    line("whole, a network namespace per child", whole)
    confine.prepare_network(whole)  # once, as the worker does: the children share it
    line("whole sandbox", whole, with_cell=True)
    line("  with a relay for the PID namespace", whole, relay=True)
    for part, setting in (("namespaces", "namespaces"), ("network namespace", "network_namespace"),
                          ("seccomp", "seccomp"), ("landlock", "landlock"), ("cgroup", "cgroup"),
                          ("user switch", "drop_user"), ("pid namespace", "pid_namespace")):
        line(f"  without {part}", dataclasses.replace(whole, **{setting: False}))
    return figures


if __name__ == "__main__":
    sys.exit(main())
