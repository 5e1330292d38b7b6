"""Tests of :mod:`autograder.sandbox.cgroups`, :mod:`autograder.sandbox.pidfd` and of the
sweeps that end a slot's processes.

The sweeps are in :mod:`autograder.sandbox.reaper`. The "hydra" below re-forks itself in a new session as fast as it can, so its pid
changes all the time: a sweep that lists ``/proc`` and then kills what it listed
misses it. Each sweep must leave nothing, and the check is repeated after a pause
so that a survivor would have had time to show up.
"""

from __future__ import annotations

import ctypes
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from autograder.engine.slot import claim_slot, slot_lock_dir
from autograder.sandbox.reaper import (
    _kill_listed,
    _proc_stat,
    child_pidfd,
    kill_child,
    kill_descendants,
    kill_user,
)
from autograder.sandbox import cgroups, pidfd
from autograder.sandbox.confine import enter_sandbox
from autograder.sandbox.cputime import CpuClock
from autograder.sandbox.policy import IsolationPolicy
from autograder.sandbox.support import probe_support

# Slots claimed like a grader's, held while the tests run: a grader running at the
# same time never uses (or sweeps) their user ids and cgroups.
SLOT, _SLOT_LOCK = claim_slot(100)
OTHER_SLOT, _OTHER_LOCK = claim_slot(SLOT + 1)
HYDRA_UID = IsolationPolicy().base_uid + SLOT
DEADLINE = 20.0


def require_root(what: str) -> None:
    if not probe_support().is_root:
        pytest.skip(f"Not running as root: {what} needs root.")


def require_cgroups() -> cgroups.SlotCgroup:
    require_root("a cgroup per slot")
    group = cgroups.slot_cgroup(SLOT, processes=64)
    if group is None:
        pytest.skip(f"No usable cgroup hierarchy here: {cgroups.cgroup_support()}")
    return group


def hydra(beacon: int) -> None:
    """Fork, let the parent exit, start a new session in the child; forever.

    Each generation writes a byte to ``beacon``; the pipe reaches end-of-file only
    when no generation holds it any more, which is how the tests tell that none is
    left (a listing of /proc can miss a process whose pid changes all the time).
    Once the test has closed the read end, the next write fails and the hydra ends
    itself: a sweep that fails its test must not leave it eating the machine (and
    every later test's time) for good.
    """
    os.set_blocking(beacon, False)
    while True:
        try:
            pid = os.fork()
        except OSError:  # at the process limit: try again
            continue
        if pid:
            os._exit(0)
        try:
            os.setsid()
            os.write(beacon, b".")
        except BrokenPipeError:
            os._exit(0)
        except OSError:
            pass


def wait_for_beacon(read_fd: int) -> None:
    """Until the hydra has written (it runs)."""
    end = time.monotonic() + DEADLINE
    while not select.select([read_fd], [], [], 0.1)[0]:
        if time.monotonic() > end:
            pytest.fail("the hydra did not start")
    assert os.read(read_fd, 1 << 16), "the hydra ended by itself"


def beacon_closed(read_fd: int) -> bool:
    """True once every holder of the pipe's write end is gone (read returns EOF)."""
    end = time.monotonic() + DEADLINE
    while time.monotonic() < end:
        if select.select([read_fd], [], [], 0.1)[0] and os.read(read_fd, 1 << 16) == b"":
            return True
    return False


def uid_processes(uid: int) -> list[int]:
    found = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                lines = Path(f"/proc/{name}/status").read_text().splitlines()
            except OSError:
                continue
            fields = dict(line.split(":", 1) for line in lines if ":" in line)
            if int(fields["Uid"].split()[0]) == uid and fields["State"].split()[0] != "Z":
                found.append(int(name))
    return found


@pytest.fixture
def reaped() -> Iterator[list[int]]:
    """Pids forked by a test; reaped (and killed if needed) at the end."""
    pids: list[int] = []
    yield pids
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:
            pass


# ----------------------------------------------------------------------- cgroups

def test_every_slot_gets_the_same_cpu_weight() -> None:
    group = require_cgroups()
    other = cgroups.slot_cgroup(OTHER_SLOT, processes=64)
    assert other is not None
    for name in ("cpu.shares", "cpu.weight"):
        values = {(d / name).read_text() for g in (group, other) for d in g.dirs if (d / name).exists()}
        assert len(values) <= 1, f"{name} differs between slots: {values}"
    assert any((d / "cpu.shares").exists() or (d / "cpu.weight").exists() for d in group.dirs)


def sandboxed_child_cgroups(workdir: Path, reaped: list[int]) -> str:
    """The sandbox's notes and ``/proc/self/cgroup`` of a child that entered it in slot SLOT."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            notes = enter_sandbox(IsolationPolicy(), workdir, slot=SLOT)
            os.write(write_fd, ("\n".join(notes) + "\n" + Path("/proc/self/cgroup").read_text())
                     .encode())
        finally:
            os._exit(0)
    reaped.append(pid)
    os.close(write_fd)
    with os.fdopen(read_fd, "rb") as pipe:
        text = pipe.read().decode()
    # The pipe closes as the child exits, a moment before it leaves the cgroup: wait for
    # it, so that a test reading the cgroup's processes next does not see it leaving.
    os.waitpid(pid, 0)
    return text


def test_child_enters_its_slot_cgroup(tmp_path: Path, reaped: list[int]) -> None:
    require_cgroups()
    text = sandboxed_child_cgroups(tmp_path, reaped)
    assert f"/{cgroups.GROUP}/slot-{SLOT}" in text, text


def test_a_child_makes_its_slot_cgroup_again_if_it_was_removed(tmp_path: Path,
                                                              reaped: list[int]) -> None:
    # The warm parent makes the slot's cgroup once and its children only join it; one
    # removed meanwhile (by an administrator, a clean-up script) is made again.
    group = require_cgroups()
    assert group.kill_all()
    for directory in group.dirs + ((group.freezer,) if group.freezer else ()):
        directory.rmdir()
    text = sandboxed_child_cgroups(tmp_path, reaped)
    assert f"/{cgroups.GROUP}/slot-{SLOT}" in text, text
    assert all(directory.is_dir() for directory in group.dirs)
    assert (cgroups.slot_cgroup(SLOT, processes=64, create=False) or group).pids() == set()


def test_a_sweep_waits_for_a_killed_child_without_a_kill_round(
        reaped: list[int], monkeypatch: pytest.MonkeyPatch) -> None:
    group = require_cgroups()
    rounds: list[int] = []
    kill_round = cgroups.SlotCgroup._kill_round

    def counted(self: cgroups.SlotCgroup, killed: dict[int, int]) -> None:
        rounds.append(len(killed))
        kill_round(self, killed)

    monkeypatch.setattr(cgroups.SlotCgroup, "_kill_round", counted)
    read_fd, write_fd = os.pipe()
    started = []
    for _ in range(2):
        pid = os.fork()
        if pid == 0:
            try:
                group.join()
                os.write(write_fd, b".")
                time.sleep(60)
            finally:
                os._exit(0)
        reaped.append(pid)
        started.append(pid)
    for _ in started:
        assert os.read(read_fd, 1) == b"."
    os.close(read_fd)
    os.close(write_fd)
    known, other = started
    fd = os.pidfd_open(known)
    signal.pidfd_send_signal(fd, signal.SIGKILL)
    # The one the caller killed is only waited for; the other is killed by a round.
    assert group.kill_all(killed={known: fd})
    assert group.pids() == set()
    assert len(rounds) == 1
    rounds.clear()
    pid = os.fork()
    if pid == 0:
        try:
            group.join()
            time.sleep(60)
        finally:
            os._exit(0)
    reaped.append(pid)
    deadline = time.monotonic() + DEADLINE
    while pid not in group.pids() and time.monotonic() < deadline:
        time.sleep(0.01)
    fd = os.pidfd_open(pid)
    signal.pidfd_send_signal(fd, signal.SIGKILL)
    assert group.kill_all(killed={pid: fd})
    assert rounds == [], "a killed child alone in the slot needs no kill round"


def _open_files() -> set[str]:
    """What this process's descriptors point to (the listing's own descriptor left out)."""
    found = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            found.add(f"{fd} {os.readlink(f'/proc/self/fd/{fd}')}")
        except OSError:
            pass
    return found


def test_the_clock_keeps_the_slot_usage_file_open_reads_it_afresh_and_closes_it() -> None:
    # As root the clock reads the slot cgroup's usage at the end of every call: one
    # file, opened once (an open, read and close per call cost ten times a pread).
    group = require_cgroups()
    assert group.usage is not None
    burner = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nsys.stdin.readline()\n"
         "while time.process_time() < 0.3:\n    pass\nprint('done', flush=True)\n"
         "sys.stdin.readline()\n"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, preexec_fn=group.join)
    try:
        before = _open_files()
        clock = CpuClock(burner.pid, usage=group)
        assert clock.usage is group  # the usage file was readable: the cgroup counts
        clock.start()
        assert any(entry.endswith(f" {group.usage}") for entry in _open_files() - before)
        assert clock.own() < 0.1
        assert burner.stdin is not None and burner.stdout is not None
        burner.stdin.write("go\n")
        burner.stdin.flush()
        assert burner.stdout.readline().strip() == "done"
        assert clock.own() >= 0.25  # the same open file, read again
        clock.close()
        assert _open_files() == before
    finally:
        burner.kill()
        burner.wait()
        assert group.kill_all()


def test_kill_all_ends_a_process_that_reforks(reaped: list[int]) -> None:
    group = require_cgroups()
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(read_fd)
            group.join()
            os.setresuid(HYDRA_UID, HYDRA_UID, HYDRA_UID)
            hydra(write_fd)
        finally:
            os._exit(0)
    reaped.append(pid)
    os.close(write_fd)
    try:
        wait_for_beacon(read_fd)
        time.sleep(0.2)  # let it re-fork many times
        assert group.kill_all()
        assert beacon_closed(read_fd), "a process of the hydra survived"
        assert group.pids() == set()
    finally:
        os.close(read_fd)


def test_pids_max_caps_the_slot(reaped: list[int]) -> None:
    group = require_cgroups()
    limit = cgroups.slot_cgroup(SLOT, processes=5)
    assert limit is not None
    pids_dir = next((d for d in group.dirs if (d / "pids.max").exists()), None)
    if pids_dir is None:
        pytest.skip("the pids controller is not mounted")
    assert (pids_dir / "pids.max").read_text().strip() == "5"
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        count = 0
        try:
            group.join()
            try:
                for _ in range(50):
                    if os.fork() == 0:
                        time.sleep(30)
                        os._exit(0)
                    count += 1
            except OSError:
                pass
            os.write(write_fd, str(count).encode())
        finally:
            os._exit(0)
    reaped.append(pid)
    os.close(write_fd)
    with os.fdopen(read_fd, "rb") as pipe:
        forked = int(pipe.read() or b"-1")
    group.kill_all()
    cgroups.slot_cgroup(SLOT, processes=64)
    assert 0 <= forked < 5


# ------------------------------------------------------------------------ sweeps

def test_kill_user_ends_a_process_that_reforks(reaped: list[int]) -> None:
    require_root("a user of the slot's own")
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(read_fd)
            os.setresuid(HYDRA_UID, HYDRA_UID, HYDRA_UID)
            hydra(write_fd)
        finally:
            os._exit(0)
    reaped.append(pid)
    os.close(write_fd)
    try:
        wait_for_beacon(read_fd)
        time.sleep(0.2)
        assert kill_user(HYDRA_UID)
        assert beacon_closed(read_fd), "a process of the hydra survived"
        assert uid_processes(HYDRA_UID) == []
    finally:
        os.close(read_fd)


def test_kill_descendants_ends_a_process_that_reforks(reaped: list[int]) -> None:
    """The non-root sweep: the warm parent is a subreaper, orphans stay below it."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            os.close(read_fd)
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(36, 1, 0, 0, 0)  # PR_SET_CHILD_SUBREAPER
            if os.fork() == 0:
                hydra(write_fd)
            os.close(write_fd)
            while True:  # reap adopted orphans, as the warm parent does
                try:
                    os.wait()
                except ChildProcessError:
                    time.sleep(0.01)
        finally:
            os._exit(0)
    reaped.append(pid)
    os.close(write_fd)
    try:
        wait_for_beacon(read_fd)
        time.sleep(0.2)
        assert kill_descendants(pid)
        assert beacon_closed(read_fd), "a process of the hydra survived"
        assert os.waitpid(pid, os.WNOHANG) == (0, 0), "the warm parent itself must survive"
    finally:
        os.close(read_fd)


def test_slot_lock_folder_is_per_user_except_root() -> None:
    folder = slot_lock_dir()
    if os.geteuid() == 0:
        assert folder == Path("/run/autograder-slots")
    else:
        assert folder.name == f"autograder-slots-{os.geteuid()}"


def claim_as(uid: int | None) -> str:
    """claim_slot() in a forked child, as ``uid`` (None: as this process); its answer."""
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:
        try:
            if uid is not None:
                os.setgroups([])
                os.setresgid(uid, uid, uid)
                os.setresuid(uid, uid, uid)
            slot, fd = claim_slot()
            os.write(write_fd, f"slot {slot} in {slot_lock_dir()}".encode())
            os.close(fd)
        except BaseException as exc:
            os.write(write_fd, f"{type(exc).__name__}: {exc}".encode())
        finally:
            os._exit(0)
    os.close(write_fd)
    with os.fdopen(read_fd, "rb") as pipe:
        answer = pipe.read().decode()
    os.waitpid(pid, 0)
    return answer


@pytest.mark.parametrize("order", [("root", "user"), ("user", "root")])
def test_root_and_ordinary_users_claim_slots_in_any_order(order: tuple[str, str]) -> None:
    require_root("switching between root and an ordinary user")
    uid = 62001
    answers = [claim_as(None if who == "root" else uid) for who in order]
    for who, answer in zip(order, answers):
        assert answer.startswith("slot "), f"{who} could not claim a slot: {answer}"
    assert any("/run/autograder-slots" in a for a in answers)
    assert any(f"autograder-slots-{uid}" in a for a in answers)


def test_a_lock_folder_planted_by_another_user_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    require_root("planting a folder as another user")
    uid = 62002
    shared = Path(tempfile.mkdtemp(dir="/tmp"))  # pytest's own tmp_path is mode 700
    shared.chmod(0o1777)
    monkeypatch.setattr(tempfile, "tempdir", str(shared))
    planted = shared / f"autograder-slots-{uid}"
    planted.mkdir()
    planted.chmod(0o777)  # owned by root, open to all: not the grader's own
    try:
        answer = claim_as(uid)
    finally:
        shutil.rmtree(shared, ignore_errors=True)
    assert answer.startswith("AutograderError") and "not a private folder" in answer, answer


# ------------------------------------------------------ signals never go by a stale number

def sleeper(*, uid: int | None = None, session: bool = False) -> int:
    """A forked child that sleeps (as ``uid``, in a session of its own if asked)."""
    pid = os.fork()
    if pid == 0:
        try:
            if session:
                os.setsid()
            if uid is not None:
                os.setresuid(uid, uid, uid)
            time.sleep(60)
        finally:
            os._exit(0)
    return pid


def alive(pid: int) -> bool:
    """Whether our child ``pid`` is still running (it is reaped if it ended)."""
    return os.waitpid(pid, os.WNOHANG) == (0, 0)


def reuse_number(number: int, reaped: list[int]) -> int | None:
    """A new sleeping child, leading a session, whose pid is ``number`` (None if the
    kernel would not give it in a few tries: other processes fork meanwhile)."""
    last_pid = Path("/proc/sys/kernel/ns_last_pid")
    for _ in range(50):
        try:
            last_pid.write_text(str(number - 1))
        except OSError:
            return None
        pid = sleeper(session=True)
        reaped.append(pid)
        if pid == number:
            end = time.monotonic() + DEADLINE
            while os.getsid(pid) != pid and time.monotonic() < end:
                time.sleep(0.001)  # until it leads its session: a group `killpg` would hit
            return pid
        os.kill(pid, signal.SIGKILL)
    return None


def dead_child_pidfd(reaped: list[int]) -> tuple[int, int]:
    """(pid, pidfd) of a child that led a session, then was killed and reaped."""
    pid = sleeper(session=True)
    fd = os.pidfd_open(pid)
    while os.getsid(pid) != pid:
        time.sleep(0.001)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return pid, fd


def test_killing_a_reaped_child_spares_the_process_that_got_its_number(reaped: list[int]) -> None:
    """The warm parent reaps a child at once; its number, and group, may then be another's."""
    require_root("choosing the next pid (ns_last_pid)")
    if not pidfd.pidfds_supported():
        pytest.skip("no pidfds on this kernel (Linux 5.3+)")
    pid, fd = dead_child_pidfd(reaped)
    try:
        newcomer = reuse_number(pid, reaped)
        if newcomer is None:
            pytest.skip(f"could not get pid {pid} again (ns_last_pid, or a busy machine)")
        kill_child(pid, fd)
        time.sleep(0.05)
        assert alive(newcomer), "kill_child signalled the new holder of a reaped child's number"
    finally:
        os.close(fd)


def test_the_group_is_killed_after_its_leader_was_reaped(reaped: list[int]) -> None:
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # a leader whose child outlives it, holding the pipe
        try:
            os.close(read_fd)
            os.setsid()
            if os.fork() == 0:
                time.sleep(60)
        finally:
            os._exit(0)
    os.close(write_fd)
    fd = os.pidfd_open(pid)
    try:
        os.waitpid(pid, 0)  # reaped, as the warm parent does
        try:
            signal.pidfd_send_signal(fd, 0, None, pidfd.PIDFD_SIGNAL_PROCESS_GROUP)
        except OSError:
            pytest.skip("no PIDFD_SIGNAL_PROCESS_GROUP on this kernel (Linux 6.9+)")
        kill_child(pid, fd)
        assert beacon_closed(read_fd), "the reaped leader's group survived"
    finally:
        os.close(fd)
        os.close(read_fd)


def test_child_pidfd_needs_the_warm_parent_as_parent(reaped: list[int]) -> None:
    if not pidfd.pidfds_supported():
        pytest.skip("no pidfds on this kernel (Linux 5.3+)")
    pid = sleeper()
    reaped.append(pid)
    assert child_pidfd(pid, 1) is None  # not init's child
    fd = child_pidfd(pid, os.getpid())
    assert fd is not None
    os.close(fd)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    assert child_pidfd(pid, os.getpid()) is None  # reaped: nothing to name


def test_a_listed_process_is_killed_only_if_it_is_still_the_one_listed(reaped: list[int]) -> None:
    pid = sleeper()
    reaped.append(pid)
    started = _proc_stat(pid).started  # type: ignore[union-attr]
    _kill_listed(pid, started + 1)  # another process that once had this number
    time.sleep(0.05)
    assert alive(pid)
    _kill_listed(pid, started)
    os.waitpid(pid, 0)  # it ends


def test_signal_listed_kills_only_numbers_listed_again(reaped: list[int]) -> None:
    if not pidfd.pidfds_supported():
        pytest.skip("no pidfds on this kernel (Linux 5.3+)")
    pid = sleeper()
    reaped.append(pid)
    killed: dict[int, int] = {}
    listings = iter([{pid}, set()])  # gone from the list by the second reading
    pidfd.signal_listed(lambda: next(listings), killed)
    time.sleep(0.05)
    assert alive(pid) and killed == {}
    pidfd.signal_listed(lambda: {pid}, killed)
    os.waitpid(pid, 0)
    assert list(killed) == [pid]
    for fd in killed.values():
        os.close(fd)


def test_kill_user_spares_other_users_and_leaves_the_grader_root(reaped: list[int]) -> None:
    require_root("users of the slots' own")
    other_uid = IsolationPolicy().base_uid + OTHER_SLOT
    target, bystander = sleeper(uid=HYDRA_UID), sleeper(uid=other_uid)
    reaped.extend([target, bystander])
    time.sleep(0.1)  # both have taken their uid
    before = Path("/proc/self/status").read_text()
    assert kill_user(HYDRA_UID)
    os.waitpid(target, 0)
    assert alive(bystander)
    assert uid_processes(HYDRA_UID) == []
    assert os.getresuid() == (0, 0, 0)
    after = Path("/proc/self/status").read_text()
    for field in ("Uid:", "CapEff:", "CapPrm:"):
        assert [l for l in after.splitlines() if l.startswith(field)] == \
            [l for l in before.splitlines() if l.startswith(field)]
