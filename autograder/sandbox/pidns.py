"""A PID namespace of its own for each sandboxed child, and a ``/proc`` that shows only it.

Without one, student code sees every process of the machine: the grader's command
line (``/proc/<pid>/cmdline``, naming the batch's folders), the workers of other
submissions, and can probe any pid with ``kill(pid, 0)``. With one, the student's
first process is pid 1 of a fresh namespace, ``/proc`` is remounted in the child's
mount namespace to show that namespace only, and no process outside it has a
number the student can name.

``unshare(CLONE_NEWPID)`` moves only the caller's *future* children into the new
namespace. As root, the warm parent makes the namespace just before it forks
(:func:`fork`): the child is born as its first process and goes on into the sandbox,
and the parent's later children are born in its own namespace again. Otherwise (an
ordinary user gets the capability only inside the child's user namespace) the child
forks once more (:func:`split_off_init`): the process the grader forked stays outside
as a small relay that closes every descriptor, waits
for the namespace's first process and exits with its status; the first process
returns and goes on into the sandbox. The relay keeps the grader's view whole: it
is the process the grader holds a pidfd of, its session and process group hold
everything the submission starts, and its parent is the warm parent. When the
namespace's first process ends, the kernel kills every other process of the
namespace. Processes orphaned inside the namespace are re-parented to that first
process (not to the warm parent): their CPU time is counted from there
(:mod:`autograder.sandbox.cputime`).

Why by hand: ``unshare(1) --pid --fork --mount-proc`` does the same but starts a
new program, which would throw away the warm interpreter.
"""

from __future__ import annotations

import os
import resource
import signal

from autograder.sandbox import kernel

__all__ = ["CLONE_NEWPID", "OFF", "born_as_init", "fork", "mount_proc", "split_off_init"]

# <sched.h>
CLONE_NEWPID = 0x20000000
# <linux/prctl.h>
PR_SET_PDEATHSIG = 1
# <sys/mount.h>
MS_NOSUID, MS_NODEV, MS_NOEXEC = 0x2, 0x4, 0x8
#: what a child without the namespace is open to, for the notes
OFF = ("other processes (the grader's command line, other submissions' workers) are "
       "visible to the submission")
#: exit status of a relay that lost its child without a status to pass on
LOST = 70


def fork(*, new_namespace: bool) -> int:
    """``os.fork()``; with ``new_namespace``, the child is process 1 of a PID namespace of its own.

    The namespace is made in the caller just before the fork and the caller's next
    children are born in its own namespace again, so the child needs no relay
    (:func:`split_off_init`): one fork, one exit and one process fewer per child
    (``benchmarks/sandbox_costs.py``). Needs ``CAP_SYS_ADMIN`` (root); where the kernel
    refuses, the child is forked as usual and makes its namespace itself.
    """
    made = new_namespace and _unshare_for_children()
    try:
        pid = os.fork()
    except BaseException:
        if made:
            _children_in_own_namespace()
        raise
    if pid != 0 and made:
        _children_in_own_namespace()
    return pid


def born_as_init() -> bool:
    """Whether this process was born as process 1 of a fresh PID namespace (see :func:`fork`).

    A child forked into its parent's namespace never has pid 1 there.
    """
    return os.getpid() == 1


def _unshare_for_children() -> bool:
    try:
        kernel.unshare(CLONE_NEWPID)
    except OSError:  # not root, or a container that refuses: the child makes its own
        return False
    return True


def _children_in_own_namespace() -> None:
    """The caller's next children are born in its own PID namespace again.

    Without this, the next fork would go into the namespace just made, whose first
    process is the child; once that child has ended the fork would fail.
    """
    fd = os.open("/proc/self/ns/pid", os.O_RDONLY | os.O_CLOEXEC)
    try:
        kernel.setns(fd, CLONE_NEWPID)
    finally:
        os.close(fd)


def split_off_init() -> None:
    """Fork the new PID namespace's first process, which returns; the caller never does.

    Call right after ``unshare(CLONE_NEWPID)`` in the single-threaded child. The
    caller becomes the relay (see the module's docstring) and exits when the first
    process ends, with its exit status (killed by the same signal, if it was).
    """
    parent = os.getppid()
    pid = os.fork()
    if pid == 0:
        return
    code = LOST
    try:
        code = _relay(pid, parent)
    finally:
        os._exit(code)


def _relay(child: int, parent: int) -> int:
    kernel.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)  # the warm parent's end ends us...
    if os.getppid() != parent:  # ... even when it came before the line above
        os.kill(child, signal.SIGKILL)
        return LOST
    # The socket to the grader must close when the first process ends, and nothing
    # else of the warm parent's is needed here.
    os.closerange(3, os.sysconf("SC_OPEN_MAX"))
    while True:
        try:
            _, status = os.waitpid(child, 0)
        except InterruptedError:
            continue
        except ChildProcessError:
            return LOST
        code = os.waitstatus_to_exitcode(status)
        if code < 0:  # killed: end the same way, so the warm parent sees what happened
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
            if -code != signal.SIGKILL:
                signal.signal(-code, signal.SIG_DFL)
            os.kill(os.getpid(), -code)
        return code if code >= 0 else 128 - code


def mount_proc() -> str:
    """In the namespace's first process: mount a ``/proc`` of this namespace over ``/proc``.

    Needs the mount namespace to be the child's own (and, for an ordinary user, a
    ``/proc`` the kernel considers fully visible: not one with masked entries, as
    some containers have). Returns the note for the result.
    """
    kernel.mount("proc", "/proc", "proc", MS_NOSUID | MS_NODEV | MS_NOEXEC, None)
    return "PID namespace: the submission's processes see only themselves (/proc remounted)"
