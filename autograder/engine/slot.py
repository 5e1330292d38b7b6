"""A grading slot: its claim, its private folders and its warm parent.

A :class:`GradingSlot` claims a slot number no other grader of this user holds
(:func:`claim_slot`) and owns one warm parent process (``python -m autograder.worker``)
that forks a sandboxed child per submission; :mod:`autograder.engine.student_process`
runs a submission in such a child.

A batch's later slots need not import again: :meth:`GradingSlot.warm_copies` has
the first slot's warm parent, before its first submission, fork copies of itself
that this grader adopts as its own children, and another slot takes one over with
:meth:`GradingSlot.adopt` (``--jobs N``, see :mod:`autograder.runners.local`).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import signal
import socket
import stat
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from autograder.errors import AutograderError, ProtocolError
from autograder.sandbox import affinity, kernel
from autograder.sandbox.pidfd import pidfd_kill, pidfd_open, pidfds_supported
from autograder.sandbox.tempdirs import OwnedFolder

# Not imported here: the frame codec (numpy) and the reaper (the sandbox's probes, whose
# seccomp binding runs ``ldconfig`` twice as it loads) take about 0.1 s, and
# :func:`start_early` launches the warm parent before either is needed, so that the
# warm parent's own imports, which come before the first result, start that much sooner.
# Each method below imports what it uses; later imports find them loaded.

#: how long the warm parent may take to import numpy, scipy and matplotlib (our own
#: process, not student code: generous, so a loaded machine is slow but never wrong)
STARTUP_TIMEOUT = 600.0
#: where root graders claim slots (one lock file per sandbox user id): under /run, which
#: only root may write, so no other user can plant the folder or its files beforehand
ROOT_SLOT_LOCKS = Path("/run/autograder-slots")
MAX_SLOTS = 1000


def slot_lock_dir() -> Path:
    """The folder of slot locks for this grader's user.

    Root graders share one folder, because their slots pick sandbox user ids that
    must never be used by two graders at once. An ordinary user's children run as
    that user, so its graders share a folder of their own
    (``$TMPDIR/autograder-slots-<uid>``): root's folder never locks them out, and
    theirs never blocks root.
    """
    uid = os.geteuid()
    if uid == 0 and ROOT_SLOT_LOCKS.parent.is_dir():
        return ROOT_SLOT_LOCKS
    return Path(tempfile.gettempdir()) / f"autograder-slots-{uid}"


def _private_folder(path: Path) -> Path:
    """Create ``path`` (mode 700) or check that the existing one is ours and private.

    A folder another user made in a shared ``/tmp`` (or a link in its place) could
    hold links to other files or lock us out; it is refused with a clear message.
    """
    try:
        path.mkdir(mode=0o700)
    except FileExistsError:
        pass
    info = os.lstat(path)
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.geteuid() or info.st_mode & 0o077:
        raise AutograderError(
            f"the slot lock folder {path} is not a private folder of this user (owner uid "
            f"{info.st_uid}, mode {stat.S_IMODE(info.st_mode):o}); remove it, or set TMPDIR "
            "to a folder of your own, and start the grader again.")
    return path


def claim_slot(first: int = 0) -> tuple[int, int]:
    """Claim a slot number no other grader of this user holds; return (slot, lock fd).

    As root, the slot picks the sandbox's user id (``base_uid + slot``) and cgroup,
    and the grader kills every process of that user after each submission, so two
    graders running at the same time (two courses, two CI jobs) must never share
    one. An exclusive ``flock`` held for the slot's lifetime guarantees that, and the
    kernel releases it if the grader dies. Lock files are opened without following
    links.
    """
    folder = _private_folder(slot_lock_dir())
    for slot in range(first, first + MAX_SLOTS):
        fd = os.open(folder / f"{slot}.lock",
                     os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        return slot, fd
    raise AutograderError(f"all {MAX_SLOTS} worker slots in {folder} are taken; "
                          "is another grader stuck?")


def matplotlib_folder() -> Path:
    """Matplotlib's folder for the warm parents of this user, kept from run to run.

    In the private folder of :func:`slot_lock_dir`: matplotlib builds its font list
    there once (about half a CPU second) instead of at every warm parent's start, and
    no other user can plant a file in it. The sandboxed children have one of their own.
    """
    folder = _private_folder(slot_lock_dir()) / "matplotlib"
    folder.mkdir(mode=0o700, exist_ok=True)
    return folder


class _Copy:
    """A warm parent this slot took over (:meth:`GradingSlot.adopt`): the few calls of
    :class:`subprocess.Popen` the slot makes, through a pidfd, since the process is
    another grader process's child (that process reaps it)."""

    stderr = None

    def __init__(self, pid: int, pidfd: int) -> None:
        self.pid, self._pidfd = pid, pidfd
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None and select.select([self._pidfd], [], [], 0)[0]:
            self.returncode = -signal.SIGKILL  # its exit status is its parent's to read
            os.close(self._pidfd)
        return self.returncode

    def kill(self) -> None:
        if self.poll() is None:
            pidfd_kill(self._pidfd)

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            if not select.select([self._pidfd], [], [], timeout)[0]:
                raise subprocess.TimeoutExpired(f"warm parent {self.pid}", timeout or 0.0)
            self.poll()
        assert self.returncode is not None
        return self.returncode


def _own_child(pid: int) -> bool:
    """Whether ``pid`` is an unreaped child of this process (so the number is still its own)."""
    try:
        return os.waitpid(pid, os.WNOHANG) == (0, 0)
    except ChildProcessError:  # not ours, or reaped already
        return False


class GradingSlot:
    """One warm parent process; forks a sandboxed child per submission."""

    def __init__(self, *, slot: int = 0, python: str = sys.executable,
                 scratch: Path | None = None) -> None:
        self.slot, self._lock = claim_slot(slot)
        try:
            #: the core the warm parent and its children run on (see autograder.sandbox.affinity)
            self.core = affinity.slot_core(self.slot)
        except BaseException:  # a bad AUTOGRADER_PIN_CORES: the slot is not kept
            os.close(self._lock)
            raise
        self._python = python
        self._proc: subprocess.Popen[bytes] | _Copy | None = None
        self._control: socket.socket | None = None
        self._greeted = False  # the running warm parent said hello: it is ready to fork
        self._copies: list[int] = []  # warm parents forked for other slots: ours to reap
        # Under ``scratch`` when the caller has a folder that is cleaned up for it (a Dask
        # worker's own directory, which Dask removes even after the worker was killed).
        # Locked while this slot lives: the next slot removes it if this grader is killed.
        self._folder = OwnedFolder(prefix="autograder-slot-", parent=scratch)
        self._home = self._folder.path
        #: every submission's working directory is made in here (see StudentProcess);
        #: traversable (711) for the slot's sandbox user, readable by nobody else
        self.work_root = self._home / "work"
        self.work_root.mkdir(mode=0o711)
        os.chmod(self.work_root, 0o711)  # mkdir's mode is masked by the umask
        #: the grader's own scratch (a submission's files unpacked before grading):
        #: beside ``work_root``, never in it, so no child's ruleset grants it; private to
        #: the grader's user, and removed with the slot's folder, by the next grader
        #: when this one is killed
        self.intake_root = self._home / "intake"
        self.intake_root.mkdir(mode=0o700)
        os.chmod(self._home, 0o711)

    def start(self, *, wait: bool = True) -> None:
        """Start the warm parent unless it runs; with ``wait``, return once it is ready.

        ``wait=False`` returns at once, so its imports run while the caller works (the
        next :meth:`spawn`, or ``start()``, waits for its hello).
        """
        if self._proc is None or self._proc.poll() is not None:
            self.close()
            self._launch()
        if wait and not self._greeted:
            self._greet()

    @property
    def warm(self) -> bool:
        """Whether the warm parent runs and said hello: a :meth:`spawn` now waits for no import."""
        return self._greeted and self._proc is not None and self._proc.poll() is None

    def _launch(self) -> None:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        env = {k: v for k, v in os.environ.items() if k in ("PATH", "LANG", "LC_ALL", "HOME")}
        env.update(MPLBACKEND="Agg", MPLCONFIGDIR=str(matplotlib_folder()),
                   OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
                   PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self._proc = subprocess.Popen(
            [self._python, "-m", "autograder.worker", "--control-fd", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),), cwd=self._home, env=env,
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        theirs.close()
        affinity.pin_process(self._proc.pid, self.core)  # before it starts any thread
        self._control = ours
        self._greeted = False

    def _greet(self) -> None:
        from autograder.boundary import frames

        assert self._control is not None
        try:
            hello = frames.recv_message(self._control, timeout=STARTUP_TIMEOUT)
        except (EOFError, OSError, ProtocolError) as exc:
            detail = self._stderr_tail()
            self.close()
            raise AutograderError(f"the grading worker did not start: {exc}. {detail}") from exc
        if not isinstance(hello, dict) or hello.get("op") != "hello":
            self.close()
            raise AutograderError("the grading worker sent an unexpected greeting")
        self._greeted = True

    def _stderr_tail(self) -> str:
        if self._proc is None or self._proc.stderr is None:
            return ""
        try:
            self._proc.wait(timeout=1)
            return self._proc.stderr.read()[-2000:].decode("utf-8", "replace")
        except subprocess.TimeoutExpired:
            return ""

    def spawn(self, request: dict[str, Any]) -> tuple[int, socket.socket]:
        """Fork a child for ``request``; return its pid and the grader's socket end."""
        from autograder.boundary import frames

        for attempt in (1, 2):
            self.start()
            ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            try:
                assert self._control is not None
                frames.send_message(self._control, request)
                socket.send_fds(self._control, [b"F"], [theirs.fileno()])
                answer = frames.recv_message(self._control, timeout=30)
                return int(answer["pid"]), ours
            except (OSError, EOFError, ProtocolError, KeyError, TypeError):
                ours.close()
                self.close()
                if attempt == 2:
                    raise
            finally:
                theirs.close()
        raise AssertionError("unreachable")

    def warm_copies(self, count: int, *, forbid: dict[str, Any] | None = None,
                    ) -> list[tuple[int, socket.socket]]:
        """Up to ``count`` copies of this slot's warm parent, each with its control socket.

        ``forbid``: the assignment's forbidden libraries (as in a spawn request), applied
        once before the copies are made so that they inherit it. Only before this slot's
        first submission (the warm parent refuses after). Each
        copy is this process's child: it dies with this process, and
        :meth:`shutdown` kills and reaps it (the slot that adopted it normally ended
        it before). Fewer copies, or none, when the kernel has no pidfds or a copy
        fails: the slots left start their own warm parents.
        """
        from autograder.boundary import frames

        copies: list[tuple[int, socket.socket]] = []
        if count <= 0 or not pidfds_supported():
            return copies
        try:
            self.start()
        except (AutograderError, OSError):  # the next spawn reports it; the others start their own
            return copies
        try:
            was = kernel.child_subreaper(True)  # the copy is adopted by this process, see worker._clone
        except OSError:  # not allowed here: the other slots start their own
            return copies
        try:
            for _ in range(count):
                ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
                try:
                    assert self._control is not None
                    frames.send_message(self._control, {"op": "clone", "forbid": forbid or {}})
                    socket.send_fds(self._control, [b"F"], [theirs.fileno()])
                    answer = frames.recv_message(self._control, timeout=30)
                except (OSError, EOFError, ProtocolError):
                    ours.close()
                    self.close()  # its state is unknown: the next spawn starts another
                    break
                finally:
                    theirs.close()
                pid = answer.get("pid") if isinstance(answer, dict) else None
                if not isinstance(pid, int) or not _own_child(pid):
                    ours.close()
                    break
                self._copies.append(pid)
                copies.append((pid, ours))
        finally:
            if not was:
                kernel.child_subreaper(False)
        return copies

    def adopt(self, pid: int, control: socket.socket) -> bool:
        """Take over a warm parent another slot's :meth:`warm_copies` made; False if it is gone.

        The next :meth:`start` waits for its hello as for one this slot launched.
        """
        pidfd = pidfd_open(pid)
        if pidfd is None:
            control.close()
            return False
        self.close()
        self._proc = _Copy(pid, pidfd)
        affinity.pin_process(pid, self.core)
        self._control = control
        return True

    @property
    def warm_parent(self) -> int | None:
        """Pid of the running warm parent (the subreaper of every child), if any."""
        return self._proc.pid if self._proc is not None and self._proc.poll() is None else None

    def close(self) -> None:
        self._greeted = False
        if self._control is not None:
            self._control.close()
            self._control = None
        if self._proc is not None:
            if self._proc.poll() is None:
                if os.geteuid() != 0:  # orphans it adopted would go to init with it
                    from autograder.sandbox.reaper import kill_descendants

                    kill_descendants(self._proc.pid)
                self._proc.kill()
            self._proc.wait()
            if self._proc.stderr is not None:
                self._proc.stderr.close()
            self._proc = None

    def disown(self) -> None:
        """In a process forked from this slot's owner: close this process's copies of the
        slot's descriptors (its lock, its folder's lock, the warm parent's socket and
        pipe), leaving the warm parent running and the folder in place: both stay the
        owner's. The object serves nothing after this (:meth:`shutdown` is a no-op).
        """
        self._greeted = False
        if self._control is not None:
            self._control.close()
            self._control = None
        if self._proc is not None and self._proc.stderr is not None:
            self._proc.stderr.close()
        self._proc = None
        self._copies.clear()
        self._folder.disown()
        if self._lock >= 0:
            os.close(self._lock)
            self._lock = -1

    def shutdown(self) -> None:
        self.close()
        for pid in self._copies:  # our children: their numbers stay theirs until reaped here
            if _own_child(pid):
                os.kill(pid, signal.SIGKILL)
                with contextlib.suppress(ChildProcessError):
                    os.waitpid(pid, 0)
        self._copies.clear()
        self._folder.remove()
        if self._lock >= 0:
            os.close(self._lock)
            self._lock = -1

    def __enter__(self) -> "GradingSlot":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()


def start_early(*, slot: int = 0) -> GradingSlot:
    """A slot whose warm parent starts now, before the caller imports the rest of the engine.

    The warm parent imports numpy, scipy, matplotlib and IPython (about a second of
    CPU) and comes before the first result; started here, it imports beside the
    caller's own imports and check collection instead of after them (0.2 s sooner
    to the first result on 2 cores). The command line's ``grade``, ``check`` and
    ``validate`` call this first thing. The caller owns the slot: it hands it to
    :class:`~autograder.engine.grader.Grader` (``worker=``) and calls
    :meth:`GradingSlot.shutdown` in the end (safe after the grader closed it too).
    """
    worker = GradingSlot(slot=slot)
    try:
        worker.start(wait=False)
    except OSError:  # it is started again when needed, and what failed is reported there
        pass
    return worker
