"""The CPU clock of a child: fresh readings from files it keeps open, and nothing left open."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from autograder.sandbox.cputime import CpuClock, process_cpu_seconds

pytestmark = pytest.mark.skipif(not os.path.exists("/proc/self/stat"),
                                reason="needs Linux's /proc (the clock reads /proc/<pid>/stat)")

#: waits for a line, computes until it has used 0.3 s of CPU, says so, waits for the end
_BURNER = ("import sys, time\n"
           "sys.stdin.readline()\n"
           "while time.process_time() < 0.3:\n"
           "    pass\n"
           "print('done', flush=True)\n"
           "sys.stdin.readline()\n")


def _open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd"))


def test_the_clock_reads_the_child_afresh_and_closes_what_it_opened() -> None:
    child = subprocess.Popen([sys.executable, "-c", _BURNER], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)
    try:
        before = _open_fds()
        clock = CpuClock(child.pid)
        clock.start()
        first_start = clock._start
        assert clock.own() < 0.1
        assert len(_open_fds() - before) == 3  # stat, schedstat and its children, kept open
        assert child.stdin is not None and child.stdout is not None
        child.stdin.write("go\n")
        child.stdin.flush()
        assert child.stdout.readline().strip() == "done"  # it has used 0.3 s of CPU
        # The same open file, read again, gives the new time (not the one read at start).
        assert clock.own() >= 0.25
        assert clock.used() >= clock.own() >= 0.25
        assert abs(clock.own() + clock._start - process_cpu_seconds(child.pid)) < 0.05
        assert clock.queued() >= 0.0
        # The next call counts from the last reading (the child waited since), not from 0.
        spent = clock.own()
        clock.start()
        assert clock._start == pytest.approx(spent + first_start) and clock.own() < 0.05
        last = clock.own()
        clock.close()
        clock.close()  # twice is harmless
        assert _open_fds() == before
        assert clock.own() == last  # a closed clock reads no file and keeps its last reading
        child.stdin.write("end\n")
        child.stdin.flush()
    finally:
        child.kill()
        child.wait()


def test_a_clock_of_a_process_that_is_gone_reads_zero() -> None:
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    clock = CpuClock(child.pid)
    clock.start()  # opens the files while the process lives
    child.wait()  # ... then it is reaped: its files read nothing
    assert clock.own() == 0.0
    assert clock.queued() == 0.0
    clock.close()
    gone = CpuClock(child.pid)  # never opened: the process is already gone
    gone.start()
    assert gone.own() == 0.0
    gone.close()
