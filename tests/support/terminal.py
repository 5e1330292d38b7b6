"""Commands started as a terminal starts them, for the tests that press Ctrl-C.

A process whose parent ignores SIGINT inherits that (a shell without job control
starts its background commands so: ``pytest &`` in a script, a CI runner's
``nohup ... &``), and Python then installs no KeyboardInterrupt handler of its own.
A test that sends SIGINT to a grading run would see it ignored (the batch went on to
its end with status 0) and would test nothing. :func:`with_ctrl_c` puts Ctrl-C's
default action back in a small launcher, which then execs the command.
"""

from __future__ import annotations

import sys
from typing import Sequence

_LAUNCHER = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
             "os.execv(sys.argv[1], sys.argv[1:])")


def with_ctrl_c(argv: Sequence[str]) -> list[str]:
    """``argv`` (its first item a path) to be run with SIGINT's default action restored."""
    return [sys.executable, "-c", _LAUNCHER, *argv]
