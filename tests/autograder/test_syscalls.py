"""Tests of :mod:`autograder.sandbox.seccomp`: namespaces, disk quota and the seccomp filter.

Each case forks a child that enters the whole sandbox (:func:`enter_sandbox`) and
tries one thing. Cases run twice when the suite runs as root: as root (the child
switches to the slot's user itself) and as an ordinary user (the forked child first
becomes uid ``ORDINARY_UID``, so ``enter_sandbox`` takes the non-root path: user
namespace, no user switch). Run as an ordinary user, only the second applies.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import select
import shutil
import signal
import socket
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from autograder.engine.slot import claim_slot
from autograder.sandbox import seccomp
from autograder.sandbox.confine import enter_sandbox
from autograder.sandbox.policy import IsolationPolicy, Limits
from autograder.sandbox.readable import readable_paths
from autograder.sandbox.support import probe_support

pyseccomp = pytest.importorskip("pyseccomp", reason="libseccomp (Debian: libseccomp2) is missing")

ORDINARY_UID = 62000  # not a slot uid (61000 + slot)
# A slot claimed like a grader's and held while the tests run, so that a grader
# running at the same time never uses or sweeps its user id.
SLOT, _SLOT_LOCK = claim_slot(200)
DEADLINE = 20.0
IDENTITIES = ["root", "user"] if os.geteuid() == 0 else ["user"]
IPPROTO_MPTCP = 262
SYSV_KEY = 0x6E67_7261  # "ngra"


@pytest.fixture(params=IDENTITIES)
def identity(request: pytest.FixtureRequest) -> str:
    if request.param == "user" and os.geteuid() != 0 and not probe_support().user_namespaces:
        pytest.skip("user namespaces are refused for this user: IPC is blocked by seccomp")
    return str(request.param)


@pytest.fixture
def workdir(identity: str) -> Iterator[Path]:
    """A working directory the identity can enter (root's tmp_path is mode 700)."""
    top = Path(tempfile.mkdtemp(prefix="syscalls-test-", dir="/tmp"))
    os.chmod(top, 0o711)
    path = top / "work"
    path.mkdir()
    (path / "data.txt").write_text("public data")
    if identity == "user" and os.geteuid() == 0:
        os.chown(path, ORDINARY_UID, ORDINARY_UID)
        os.chown(path / "data.txt", ORDINARY_UID, ORDINARY_UID)
    yield path
    shutil.rmtree(top, ignore_errors=True)


def run(action: Callable[[], Any], workdir: Path, identity: str, *,
        policy: IsolationPolicy | None = None, slot: int | None = None) -> dict[str, Any]:
    """Fork; become ``identity``; enter the sandbox; run ``action``; return its report."""
    policy = policy or IsolationPolicy()
    slot = SLOT if slot is None else slot
    readable_paths([])  # warm the cache as the worker's parent does before forking
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        code = 70
        try:
            os.close(read_fd)
            if identity == "user" and os.geteuid() == 0:
                os.setgroups([])
                os.setresgid(ORDINARY_UID, ORDINARY_UID, ORDINARY_UID)
                os.setresuid(ORDINARY_UID, ORDINARY_UID, ORDINARY_UID)
            notes = enter_sandbox(policy, workdir, slot=slot)
            try:
                report: dict[str, Any] = {"value": action(), "notes": list(notes)}
            except OSError as exc:
                report = {"errno": exc.errno, "message": str(exc), "notes": list(notes)}
            os.write(write_fd, json.dumps(report).encode())
            code = 0
        finally:
            os._exit(code)
    os.close(write_fd)
    chunks = []
    end = time.monotonic() + DEADLINE
    try:
        # WNOWAIT: the child stays a zombie, so its pid (and group id) cannot be reused
        # by another process before the group is killed below.
        while time.monotonic() < end:
            if os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None:
                break
            time.sleep(0.01)
        else:
            pytest.fail("the sandboxed child did not finish")
        os.set_blocking(read_fd, False)
        try:
            while chunk := os.read(read_fd, 1 << 16):
                chunks.append(chunk)
        except BlockingIOError:
            pass
    finally:
        os.close(read_fd)
        try:
            os.killpg(pid, signal.SIGKILL)
        except OSError:
            pass
        os.waitpid(pid, 0)
    assert chunks, "the child reported nothing"
    return json.loads(b"".join(chunks))


def syscall_number(name: str) -> int:
    return pyseccomp.resolve_syscall(pyseccomp.Arch.NATIVE, name)


def raw_syscall(name: str, *args: int) -> int:
    """Call ``name`` directly (no libc wrapper); the errno, or 0 on success."""
    libc = ctypes.CDLL(None, use_errno=True)
    result = libc.syscall(ctypes.c_long(syscall_number(name)), *[ctypes.c_long(a) for a in args])
    return ctypes.get_errno() if result == -1 else 0


# ------------------------------------------------------------------------ sockets

SOCKETS = {
    "tcp": (socket.AF_INET, socket.SOCK_STREAM, 0),
    "udp": (socket.AF_INET, socket.SOCK_DGRAM, 0),
    "tcp6": (socket.AF_INET6, socket.SOCK_STREAM, 0),
    "mptcp": (socket.AF_INET, socket.SOCK_STREAM, IPPROTO_MPTCP),
    "raw": (socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_ICMP),
    "ping": (socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_ICMP),
    "unix-stream": (socket.AF_UNIX, socket.SOCK_STREAM, 0),
    "unix-dgram": (socket.AF_UNIX, socket.SOCK_DGRAM, 0),
    "netlink": (socket.AF_NETLINK, socket.SOCK_RAW, 0),
    "packet": (socket.AF_PACKET, socket.SOCK_RAW, 0),
}


@pytest.mark.parametrize("kind", sorted(SOCKETS))
def test_no_socket_of_any_family(workdir: Path, identity: str, kind: str) -> None:
    family, type_, proto = SOCKETS[kind]
    report = run(lambda: socket.socket(family, type_, proto).close(), workdir, identity)
    assert report.get("errno") == errno.EPERM, report


def test_no_socketpair(workdir: Path, identity: str) -> None:
    report = run(lambda: [s.close() for s in socket.socketpair()], workdir, identity)
    assert report.get("errno") == errno.EPERM, report


def test_unix_socket_files_receive_nothing(workdir: Path, identity: str, tmp_path: Path) -> None:
    """Listeners on a pathname and an abstract UNIX socket, reachable by any user."""
    folder = Path(tempfile.mkdtemp(dir="/tmp"))
    os.chmod(folder, 0o777)
    path = folder / "listener.sock"
    abstract = f"\0autograder-test-{os.getpid()}"
    listeners = []
    for address in (str(path), abstract):
        listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        listener.bind(address)
        listener.listen()
        listener.setblocking(False)
        listeners.append(listener)
    os.chmod(path, 0o777)

    def action() -> list[str]:
        reached = []
        for address in (str(path), abstract):
            try:
                with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
                    sock.connect(address)
                    sock.sendall(b"escaped")
                    reached.append(repr(address))
            except OSError:
                pass
        return reached

    try:
        report = run(action, workdir, identity)
        received = []
        for listener in listeners:
            try:
                received.append(listener.accept())
            except BlockingIOError:
                pass
    finally:
        for listener in listeners:
            listener.close()
        shutil.rmtree(folder, ignore_errors=True)
    assert report["value"] == [] and received == []


def test_channel_opened_before_the_sandbox_keeps_working(workdir: Path, identity: str) -> None:
    ours, theirs = socket.socketpair()
    try:
        report = run(lambda: theirs.send(b"still here"), workdir, identity)
        assert report["value"] == len(b"still here")
        assert ours.recv(64) == b"still here"
    finally:
        ours.close()
        theirs.close()


# ---------------------------------------------------- keyrings, memfd, io_uring

KEY_SPEC_PROCESS_KEYRING = -2  # <linux/keyctl.h>
KEYCTL_GET_KEYRING_ID = 0


def test_keyrings_are_out_of_reach(workdir: Path, identity: str) -> None:
    def action() -> list[int]:
        key_type, description, payload = b"user\0", b"answers\0", b"36/36"
        args = [ctypes.cast(ctypes.c_char_p(b), ctypes.c_void_p).value or 0
                for b in (key_type, description, payload)]
        return [raw_syscall("add_key", *args, len(payload), KEY_SPEC_PROCESS_KEYRING),
                raw_syscall("keyctl", KEYCTL_GET_KEYRING_ID, KEY_SPEC_PROCESS_KEYRING, 1),
                raw_syscall("request_key", args[0], args[1], 0, 0)]

    assert run(action, workdir, identity)["value"] == [errno.EPERM] * 3


def test_memfd_and_io_uring_are_refused(workdir: Path, identity: str) -> None:
    def action() -> list[int]:
        try:
            os.memfd_create("hoard")
            memfd = 0
        except OSError as exc:
            memfd = exc.errno or 0
        params = ctypes.create_string_buffer(120)  # struct io_uring_params
        address = ctypes.addressof(params)
        return [memfd, raw_syscall("io_uring_setup", 4, address)]

    assert run(action, workdir, identity)["value"] == [errno.EPERM, errno.EPERM]


# ------------------------------------------------------------------- System V IPC

def sysv_objects() -> set[int]:
    """Keys of the System V objects this (the grader's) IPC namespace holds."""
    keys = set()
    for kind in ("shm", "msg", "sem"):
        lines = Path(f"/proc/sysvipc/{kind}").read_text().splitlines()[1:]
        keys.update(int(line.split()[0]) for line in lines)
    return keys


def create_sysv_objects() -> list[int]:
    """shmget, msgget and semget with ``SYSV_KEY``: 0 for each created, else the errno."""
    libc = ctypes.CDLL(None, use_errno=True)
    ipc_creat = 0o1000
    results = []
    for call in (lambda: libc.shmget(SYSV_KEY, 1 << 20, ipc_creat | 0o666),
                 lambda: libc.msgget(SYSV_KEY, ipc_creat | 0o666),
                 lambda: libc.semget(SYSV_KEY, 1, ipc_creat | 0o666)):
        results.append(ctypes.get_errno() if call() == -1 else 0)
    return results


def find_sysv_objects() -> list[int]:
    """shmget, msgget and semget without IPC_CREAT: ENOENT where nothing is left."""
    libc = ctypes.CDLL(None, use_errno=True)
    return [ctypes.get_errno() if call() == -1 else 0
            for call in (lambda: libc.shmget(SYSV_KEY, 0, 0), lambda: libc.msgget(SYSV_KEY, 0),
                         lambda: libc.semget(SYSV_KEY, 0, 0))]


def test_sysv_objects_die_with_the_child(workdir: Path, identity: str) -> None:
    assert SYSV_KEY not in sysv_objects()
    first = run(create_sysv_objects, workdir, identity)
    assert first["value"] == [0, 0, 0], first  # allowed, in the child's own namespace
    assert any(note.startswith("namespaces: IPC") for note in first["notes"])
    assert SYSV_KEY not in sysv_objects(), "a System V object reached the grader's namespace"
    second = run(find_sysv_objects, workdir, identity)
    assert second["value"] == [errno.ENOENT] * 3, "the next child saw the previous one's objects"


def test_without_ipc_namespace_seccomp_refuses_sysv(workdir: Path, identity: str) -> None:
    policy = IsolationPolicy(namespaces=False)
    report = run(create_sysv_objects, workdir, identity, policy=policy)
    assert report["value"] == [errno.EPERM] * 3
    assert SYSV_KEY not in sysv_objects()


def test_without_either_sysv_objects_would_leak(workdir: Path, identity: str) -> None:
    """The control case: both mechanisms off, the segment outlives the child."""
    policy = IsolationPolicy(namespaces=False, seccomp=False)
    try:
        report = run(create_sysv_objects, workdir, identity, policy=policy)
        assert report["value"][0] == 0
        assert SYSV_KEY in sysv_objects()
    finally:
        libc = ctypes.CDLL(None, use_errno=True)
        for get, remove in ((lambda: libc.shmget(SYSV_KEY, 0, 0), lambda i: libc.shmctl(i, 0, None)),
                            (lambda: libc.msgget(SYSV_KEY, 0), lambda i: libc.msgctl(i, 0, None)),
                            (lambda: libc.semget(SYSV_KEY, 0, 0), lambda i: libc.semctl(i, 0, 0))):
            ident = get()
            if ident != -1:
                remove(ident)  # IPC_RMID
    assert SYSV_KEY not in sysv_objects()


# --------------------------------------------------------------------- disk quota

def test_disk_quota_bounds_the_total(workdir: Path, identity: str) -> None:
    limits = Limits(file_size_bytes=2 << 20, disk_bytes=4 << 20)

    def action() -> list[Any]:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        written = 0
        try:
            for index in range(8):
                with open(f"part{index}.bin", "wb") as handle:
                    for _ in range(2):
                        written += handle.write(b"\1" * (1 << 20))
        except OSError as exc:
            return [exc.errno, written, Path("data.txt").read_text()]
        return [0, written, ""]

    report = run(action, workdir, identity, policy=IsolationPolicy(limits=limits))
    code, written, data = report["value"]
    assert code == errno.ENOSPC and written <= 4 << 20
    assert data == "public data"  # the grader's files were copied onto the tmpfs
    assert sorted(p.name for p in workdir.iterdir()) == ["data.txt"], "files reached the grader's disk"


def test_private_namespaces_report_what_they_did(workdir: Path, identity: str) -> None:
    report = run(lambda: Path("/proc/self/mountinfo").read_text().count("tmpfs"),
                 workdir, identity)
    notes = " | ".join(report["notes"])
    assert "disk quota: tmpfs of" in notes and "seccomp: EPERM for socket" in notes
    if identity == "user":
        assert "(in a user namespace)" in notes and "network" in notes


def test_user_namespaces_allowed_is_a_bool() -> None:
    assert isinstance(seccomp.user_namespaces_allowed(), bool)


# ---------------------------------------------------------------- process group

def test_process_group_cannot_be_left(workdir: Path, identity: str) -> None:
    def action() -> list[int]:
        codes = []
        for call in (os.setsid, lambda: os.setpgid(0, 0)):
            try:
                call()
                codes.append(0)
            except OSError as exc:
                codes.append(exc.errno or 0)
        return codes

    assert run(action, workdir, identity)["value"] == [errno.EPERM, errno.EPERM]


def test_killing_the_group_ends_a_process_that_reforks(workdir: Path, identity: str) -> None:
    """A chain of processes that each fork and exit stays in the group: one killpg ends it.

    Each generation holds the write end of a pipe; end-of-file on the read end means
    none is left (a listing of /proc can miss a process whose pid keeps changing).
    """
    readable_paths([])  # imports what enter_sandbox needs while this user can read them
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(read_fd)
            if identity == "user" and os.geteuid() == 0:
                os.setgroups([])
                os.setresgid(ORDINARY_UID, ORDINARY_UID, ORDINARY_UID)
                os.setresuid(ORDINARY_UID, ORDINARY_UID, ORDINARY_UID)
            enter_sandbox(IsolationPolicy(), workdir, slot=SLOT)
            os.set_blocking(write_fd, False)
            while True:
                try:
                    if os.fork():
                        os._exit(0)
                except OSError:
                    continue
                try:
                    os.setsid()
                except OSError:
                    pass
                try:
                    os.write(write_fd, b".")
                except OSError:
                    pass
        finally:
            os._exit(0)
    os.close(write_fd)
    try:
        assert select.select([read_fd], [], [], DEADLINE)[0], "the chain did not start"
        assert os.read(read_fd, 1 << 16), "the chain ended by itself"
        time.sleep(0.3)
        # The first generation has exited but is not reaped yet: its pid, the group's
        # id, cannot have been given to another process.
        os.killpg(pid, signal.SIGKILL)
        end = time.monotonic() + DEADLINE
        closed = False
        while not closed and time.monotonic() < end:
            closed = bool(select.select([read_fd], [], [], 0.1)[0]) and os.read(read_fd, 1 << 16) == b""
        assert closed, "a process of the chain survived the group kill"
    finally:
        os.close(read_fd)
        os.waitpid(pid, 0)


def test_data_larger_than_the_quota_leave_the_directory_as_it_was(workdir: Path, identity: str) -> None:
    (workdir / "big.npy").write_bytes(b"\0" * (3 << 20))
    if identity == "user" and os.geteuid() == 0:
        os.chown(workdir / "big.npy", ORDINARY_UID, ORDINARY_UID)
    policy = IsolationPolicy(limits=Limits(disk_bytes=1 << 20))
    report = run(lambda: os.path.getsize("big.npy"), workdir, identity, policy=policy)
    assert report["value"] == 3 << 20
    assert any(note.startswith("disk quota skipped") for note in report["notes"])
