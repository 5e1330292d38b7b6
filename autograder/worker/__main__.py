"""The warm parent: import the heavy libraries once, then fork a child per submission.

Started by the grader as ``python -m autograder.worker --control-fd N``. It pays
for the interpreter and ``import numpy, scipy, matplotlib, IPython`` once per
worker slot (once per batch: the other slots of a ``--jobs N`` batch get copies of
it, see :func:`_clone`); each submission then costs a ``fork()``. The standard library's
``multiprocessing`` forkserver does the same trick but sends pickles both ways,
which the trust boundary forbids, so this small loop is written by hand.

Control messages (JSON frames from :mod:`autograder.boundary.frames`):

* grader -> parent ``{"op": "spawn", ...}`` followed by one file descriptor
  (the submission's socket, sent with ``SCM_RIGHTS``);
* parent -> grader ``{"pid": <child pid>}``;
* grader -> parent ``{"op": "clone", "forbid": ...}`` followed by one file
  descriptor (the copy's control socket), accepted only before the first spawn: the
  parent forks a copy of itself for another slot (see :func:`_clone`) and answers
  ``{"pid": <copy's pid>}``, or ``{"error": ...}``.

Nothing of a submission passes through this process (see :func:`_cells`): the
child receives its cells from the grader once it is sandboxed.
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import gc
import json
import os
import signal
import socket
import sys
import sysconfig
import time
from pathlib import Path
from typing import Any

_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:
    """Ask the kernel to SIGKILL this process when its parent goes away."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the socket EOF still ends us
        pass


#: the cyclic collector's thresholds, restored by :func:`main` before any child is forked
DEFAULT_GC_THRESHOLDS = gc.get_threshold()
#: while the warm parent starts: the imports below and the warm-up make some 140,000
#: objects that all live on, and at the default first threshold (700) the young
#: collections, and the two full ones they lead to, cost about 0.1 s of CPU (a tenth
#: of the imports) before the first result; at 20,000 they leave some 2,000 more
#: objects in the end and run no full collection
STARTUP_GC_THRESHOLDS = (20_000, 10, 10)

if __name__ == "__main__":
    # Before the heavy imports: they take seconds (matplotlib may build its font cache
    # into the slot's folder), and a grader killed meanwhile must not leave us running
    # and writing into a folder its cleanup is removing.
    _die_with_parent()
    gc.set_threshold(*STARTUP_GC_THRESHOLDS)

# Heavy imports happen here, once, before any fork.
import numpy  # noqa: F401
import scipy  # noqa: F401
import scipy.interpolate  # noqa: F401
import scipy.linalg  # noqa: F401
import scipy.spatial  # noqa: F401
import scipy.special  # noqa: F401
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot  # noqa: E402,F401
import matplotlib.tri  # noqa: E402,F401

from autograder.boundary import frames  # noqa: E402
from autograder.errors import ProtocolError  # noqa: E402

from autograder.sandbox import confine, kernel, landlock, readable  # noqa: E402
from autograder.sandbox.policy import IsolationPolicy, Limits  # noqa: E402

from autograder.sandbox import seccomp  # noqa: E402
from autograder.worker import execute  # noqa: E402
from autograder.worker import figures  # noqa: E402
from autograder.worker import guard  # noqa: E402
from autograder.worker import hugepages  # noqa: E402
from autograder.worker import loop  # noqa: E402
from autograder.worker import otter_stub  # noqa: E402

def _adopt_orphans() -> None:
    """Become the child subreaper: whatever a submission leaves behind stays below us.

    A grader that is not root has neither a user nor a cgroup per slot; it finds a
    submission's processes as the descendants of this process
    (:func:`autograder.sandbox.reaper.kill_descendants`), even those whose parent died.
    """
    try:
        kernel.child_subreaper(True)
    except (OSError, AttributeError):  # not Linux
        pass


def _reap(signum: int, frame: Any) -> None:
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def _policy(spec: dict[str, Any]) -> IsolationPolicy:
    limits = Limits(**spec.get("limits", {}))
    rest: dict[str, Any] = {k: (tuple(v) if isinstance(v, list) else v)
                            for k, v in spec.items() if k != "limits"}
    return IsolationPolicy(limits=limits, **rest)


def _child(sock: socket.socket, request: dict[str, Any], shell: execute.GradingShell,
           shared: landlock.SharedLandlock | None) -> None:
    """Enter the sandbox, run the cells, then serve calls. Never returns."""
    code = 0
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        policy = _policy(request["policy"])
        workdir = Path(request["workdir"])
        _quiet_standard_streams()
        notes = confine.enter_sandbox(policy, workdir, slot=int(request["slot"]),
                                      exclude=[Path(p) for p in request.get("exclude", [])],
                                      shared=shared)
        if shared is not None:  # enforced (and closed) above unless another was needed
            shared.close()
        _die_with_parent()
        loop.protect_channel(sock)
        gap = _unreadable_path()
        if gap is not None:
            frames.send_message(sock, {"op": "sandbox-broken", "path": gap[0], "error": gap[1]})
            return
        if _forbid_key(request) != _APPLIED[0]:  # the warm parent applied another list
            notes = (*notes, *_apply_forbid(request))
        otter_stub.install(request.get("otter"))  # an otter assignment's grader.check
        output = execute.capture_output(policy.limits.output_bytes)
        frames.send_message(sock, {"op": "started", "pid": os.getpid(), "notes": list(notes)})
        run = execute.Execution(shell, output)
        run.run(_cells(sock), lambda i: _announce(sock, i),
                lambda i: _hidden_source(sock, i, run, output))
        frames.send_message(sock, {
            "op": "ready",
            "cells": [o.to_wire() for o in run.outcomes],
            "stdout": output.take(),
            "functions": loop.defined_functions(shell),
        })
        loop.serve(sock, shell, output)
    except BaseException:  # the child must never fall back into the parent's loop
        code = 70
    finally:
        os._exit(code)


#: the forbid list the warm parent applied to itself (inherited by every child)
_APPLIED: list[str | None] = [None]
#: the Landlock ruleset built once for every child (rebuilt if the settings change)
_SHARED: list[landlock.SharedLandlock | None] = [None]
#: children forked so far
_FORKED: list[int] = [0]


def _shared_landlock(request: dict[str, Any], policy: IsolationPolicy, workdir: Path,
                     exclude: list[Path]) -> landlock.SharedLandlock | None:
    """The ruleset for this request's child, built here once for the slot's work root.

    None when the grader named no work root, or one ``workdir`` is not directly in
    (the child then builds its own).
    """
    root = request.get("workroot")
    if not isinstance(root, str) or workdir.resolve().parent != Path(root).resolve():
        return None
    current = _SHARED[0]
    if current is None or not current.serves(policy, workdir, exclude):
        if current is not None:
            current.close()
        current = _SHARED[0] = landlock.shared_landlock(policy, Path(root), exclude)
    return current


def _forbid_key(request: dict[str, Any]) -> str:
    return json.dumps(request.get("forbid") or {}, sort_keys=True)


def _apply_forbid(request: dict[str, Any]) -> list[str]:
    rules = request.get("forbid") or {}
    return guard.forbid([str(n) for n in rules.get("names", [])],
                        internal_use=[str(n) for n in rules.get("internal_use", [])],
                        reason=str(rules.get("reason", "")))


@functools.cache
def _probes() -> tuple[str, ...]:
    """The files :func:`_unreadable_path` opens (listed once, in the warm parent)."""
    stdlib = sysconfig.get_paths()["stdlib"]
    # Files only, for the standard library: its folder may be split into one rule per
    # entry (site-packages inside it holds the grader's own packages), and imports
    # use the folder listing the warm parent already cached.
    probes = [os.path.join(stdlib, "os.py"), os.path.join(stdlib, "json", "__init__.py"),
              os.path.join(stdlib, "fractions.py"), os.path.join(stdlib, "encodings")]
    for name in ("numpy", "scipy", "matplotlib", "IPython"):
        module = sys.modules.get(name)
        origin = getattr(module, "__file__", None)
        if origin:  # the file itself: a package folder may be split around a forbidden module
            probes.append(origin)
    return tuple(probes)


def _unreadable_path() -> tuple[str, str] | None:
    """The first file student code needs that the sandbox does not let it read, if any.

    The standard library, numpy, scipy, matplotlib and IPython must be readable
    wherever they are installed (a venv inside the repository, ``/autograder``,
    beside a release folder); otherwise the grader reports an engine error
    instead of letting every import in the notebook fail.
    """
    for path in _probes():
        try:
            if os.path.isdir(path):
                os.listdir(path)
            elif os.path.exists(path) or not path.endswith(".py"):
                with open(path, "rb") as handle:
                    handle.read(1)
        except OSError as exc:
            return path, exc.strerror or str(exc)
    return None


def _cells(sock: socket.socket) -> list[tuple[int, str | None]]:
    """The submission's cells, sent by the grader to this child once it is sandboxed.

    They never pass through the warm parent: what the warm parent decodes stays in
    its heap after it is freed, and every later child is a copy of that heap, so a
    submission could read the code of the submissions its slot graded before it.
    """
    message = frames.recv_message(sock)
    if not (isinstance(message, dict) and message.get("op") == "cells"
            and isinstance(message.get("cells_json"), str)):
        raise ProtocolError("the grader did not send the cells")
    return [(int(i), None if s is None else str(s)) for i, s in json.loads(message["cells_json"])]


def _announce(sock: socket.socket, index: int) -> None:
    """Tell the grader which cell starts now (so a hang is pinned to its cell)."""
    frames.send_message(sock, {"op": "cell", "index": index})


def _hidden_source(sock: socket.socket, index: int, run: execute.Execution,
                   output: execute.BoundedText) -> str:
    """Ask the grader for the source of the hidden test cell ``index``, reached now.

    It was left out of the request, so code of the cells before could not read it.
    The reports and output so far go with the question: the grader shows the
    student nothing produced after a hidden test entered this process.
    """
    frames.send_message(sock, {"op": "need-source", "index": index,
                               "cells": [o.to_wire() for o in run.outcomes],
                               "stdout": output.take()})
    answer = frames.recv_message(sock)
    if not (isinstance(answer, dict) and answer.get("op") == "source"
            and answer.get("index") == index and isinstance(answer.get("source"), str)):
        raise ProtocolError(f"the grader did not send the source of cell {index}")
    return answer["source"]


def _quiet_standard_streams() -> None:
    """Point fds 0-2 at /dev/null: C-level and subprocess output never reaches the grader."""
    null = os.open(os.devnull, os.O_RDWR)
    for fd in (0, 1, 2):
        os.dup2(null, fd)
    os.close(null)


def _serve(control: socket.socket, shell: execute.GradingShell) -> int:
    """Answer the grader's requests until its end of ``control`` closes."""
    frames.send_message(control, {"op": "hello", "pid": os.getpid(),
                                    "python": sys.version.split()[0], "time": time.time()})
    while True:
        try:
            request = frames.recv_message(control)
            _, fds, _, _ = socket.recv_fds(control, 1, 1)
        except (EOFError, OSError, ProtocolError):
            return 0
        op = request.get("op") if isinstance(request, dict) and len(fds) == 1 else None
        if op == "spawn":
            _spawn(control, request, socket.socket(fileno=fds[0]), shell)
        elif op == "clone":
            _clone(control, request, fds[0], shell)
        else:
            return 0


def _clone(control: socket.socket, request: dict[str, Any], fd: int,
           shell: execute.GradingShell) -> None:
    """Fork a warm parent for another slot of the same grader, as the grader's own child.

    The copy costs a fork instead of a second interpreter importing numpy, matplotlib
    and IPython (about a second of CPU, which on 2 cores delayed the second slot's
    first submission by as much). Only before the first spawn: nothing of a submission,
    nor of this slot's settings, has reached this process yet. The request's forbidden
    libraries (the assignment's, the same for every slot) are applied first, once, so
    the copies inherit that too (about 0.15 s each).

    The copy must not be this process's child: this process reaps its children, and a
    slot's CPU clock (an ordinary user's) counts what it reaped, and closing this slot
    kills its descendants. So the fork goes through an intermediate that exits at once
    while this process is, for that moment, no child subreaper: the copy is then
    adopted by the grader, which made itself the subreaper for the request and is the
    one that reaps it. Why by hand: ``clone(CLONE_PARENT)`` does this in one call but
    Python's ``os.fork`` is the only fork that keeps the interpreter sound.
    """
    if _FORKED[0] or _APPLIED[0] not in (None, _forbid_key(request)):
        os.close(fd)
        frames.send_message(control, {"error": "this warm parent already served a slot"})
        return
    if _APPLIED[0] is None:
        _apply_forbid(request)
        _APPLIED[0] = _forbid_key(request)
    grader = os.getppid()
    was = kernel.child_subreaper(False)
    try:
        reader, writer = os.pipe()
        middle = os.fork()
        if middle == 0:  # the intermediate: fork the copy, say its pid, exit
            try:
                os.close(reader)
                copy = os.fork()
                if copy == 0:
                    os.close(writer)
                    _become_copy(control, fd, shell, grader, os.getppid())
                os.write(writer, str(copy).encode())
            finally:
                os._exit(0)
        os.close(writer)
        with os.fdopen(reader, "rb") as answer:
            said = answer.read()
        try:
            os.waitpid(middle, 0)
        except ChildProcessError:  # reaped by the SIGCHLD handler already
            pass
    finally:
        kernel.child_subreaper(was)
        os.close(fd)
    frames.send_message(control, {"pid": int(said)} if said.isdigit()
                        else {"error": "the copy could not be forked"})


def _become_copy(control: socket.socket, fd: int, shell: execute.GradingShell,
                 grader: int, middle: int) -> None:
    """The copy: wait to be adopted by the grader, then serve on ``fd``. Never returns."""
    code = 0
    try:
        control.close()  # the first slot's: that slot's grader alone talks on it
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 2)  # not the first slot's stderr pipe, which its grader reads to EOF
        os.close(null)
        os.chdir("/")  # not the first slot's folder, which is removed when that slot ends
        deadline = time.monotonic() + 10
        while os.getppid() == middle and time.monotonic() < deadline:
            time.sleep(0.0002)
        _die_with_parent()
        if os.getppid() != grader:  # adopted by someone else: the grader is gone, or no subreaper
            os._exit(1)
        _adopt_orphans()
        code = _serve(socket.socket(fileno=fd), shell)
    except BaseException:
        code = 70
    finally:
        os._exit(code)


def _spawn(control: socket.socket, request: dict[str, Any], sub: socket.socket,
           shell: execute.GradingShell) -> None:
    # The last child, killed and swept before this request, is reaped now if it was not
    # yet: its CPU time then lands in this process's before the next child's clock starts
    # (autograder.sandbox.cputime counts the reaped children of this process).
    _reap(signal.SIGCHLD, None)
    if _APPLIED[0] is None:
        # Once per warm parent (a slot serves one assignment): unloading the forbidden
        # libraries costs ~0.1 s, which no child should pay again.
        _apply_forbid(request)
        _APPLIED[0] = _forbid_key(request)
    # Computed here, once, so every forked child inherits the cached lists (a child
    # that computed them itself would pay about half a second): the folders to cover
    # are found from the readable paths, which this fills the cache with too.
    policy, workdir = _policy(request["policy"]), Path(request["workdir"])
    exclude = [Path(p) for p in request.get("exclude", [])]
    readable.coverable_folders(exclude, workdir, policy)
    confine.prepare_cgroup(policy, int(request["slot"]))
    confine.prepare_network(policy)
    _probes()
    shared = _shared_landlock(request, policy, workdir, exclude)
    # Everything this process made moves to the collector's permanent generation: the
    # child's full collections then neither walk nor copy on write the parent's
    # objects (a cell that allocates much ran about 3x faster; benchmarks/fork_floor.py).
    gc.freeze()
    pid = confine.fork_child(policy)
    if pid == 0:
        control.close()
        _child(sub, request, shell, shared)
    sub.close()
    frames.send_message(control, {"pid": pid})
    _FORKED[0] += 1
    if _FORKED[0] == hugepages.COLLAPSE_AFTER:  # while that child runs; a short batch never pays
        hugepages.collapse()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m autograder.worker")
    parser.add_argument("--control-fd", type=int, required=True)
    args = parser.parse_args(argv)
    _adopt_orphans()
    control = socket.socket(fileno=args.control_fd)
    shell = execute.make_shell()
    execute.warm_up(shell)
    figures.close_all()
    readable.prime_caches()
    seccomp.prepare_filters()
    gc.set_threshold(*DEFAULT_GC_THRESHOLDS)  # every child collects as a fresh interpreter does
    signal.signal(signal.SIGCHLD, _reap)
    return _serve(control, shell)


if __name__ == "__main__":
    sys.exit(main())
