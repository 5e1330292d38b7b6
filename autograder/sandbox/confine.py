"""Isolation applied inside the forked worker child, just before student code runs.

The warm worker ("zygote") imports numpy, scipy, matplotlib and IPython once and
then ``os.fork()``s one child per submission. The child calls :func:`enter_sandbox`,
which, in this order:

1. starts a new session, so the grader can ``killpg`` the child and everything it forks;
2. replaces the environment (no tokens, no CI variables, not even in
   ``/proc/self/environ``) and moves into the submission's working directory;
3. sets resource limits (address space, CPU, processes, open files, file size, core);
4. as root, is in an empty network namespace (the one its warm parent made once for
   the slot, see :func:`prepare_network`, or one of its own) and switches to a user id
   of its own (``base_uid + slot``) keeping only ``CAP_DAC_READ_SEARCH``;
5. enforces a Landlock ruleset: read-only access to the Python installation and the
   system directories, full access to the working directory only, no TCP bind or
   connect, no signals or abstract UNIX sockets outside the sandbox.

Steps of :mod:`autograder.sandbox.seccomp` come in between: right after the new session,
private IPC, UTS and mount namespaces (as an ordinary user inside a user namespace)
with a size-limited tmpfs over the working directory; just before Landlock, a
seccomp filter (no new socket of any family, no keyrings, memfd or io_uring; no
System V IPC where there is no IPC namespace).

Why this is written by hand: tools such as bubblewrap, nsjail or firejail start a
*new program*, which would throw away the warm interpreter and its imported modules;
here every step must be applied in-process to a forked Python child. ``landlockpy``
wraps the Landlock system calls, but no well-kept library combines Landlock with
rlimits, namespaces and capability dropping, so the remaining system calls (``unshare``,
``prctl``, ``capset``) are called through :mod:`ctypes` below.

Already-open file descriptors (the socket to the grader, the pipes for output) keep
working: neither Landlock nor the user switch affects them.

Without the user switch (not root, or ``drop_user=False``) the child shares the
grader's uid, and Landlock does not stop it from reading ``/proc/<pid>/environ`` of
the grader's processes (it blocks ptrace attach and ``/proc/<pid>/mem`` only). Start
the grader's processes with a clean environment, or make them non-dumpable
(``prctl(PR_SET_DUMPABLE, 0)``), in that setting. Command lines in
``/proc/<pid>/cmdline`` are readable by every user, as always on Linux.
"""

from __future__ import annotations

import ctypes
import errno
import functools
import importlib.metadata
import importlib.util
import os
import resource
import site
import sys
import sysconfig
import tempfile
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from autograder.errors import UsageError
from autograder.sandbox import cgroups, seccomp

try:  # Landlock is Linux-only; elsewhere the sandbox notes its absence.
    import landlockpy
    from landlockpy import AccessFS, AccessNet, RestrictFlag, Ruleset, Scope

    #: what the child may do in a readable root (everything else is about changing files)
    _READ_RIGHTS = AccessFS.READ_FILE | AccessFS.READ_DIR | AccessFS.EXECUTE
except ImportError:  # pragma: no cover - landlockpy is a Linux dependency
    landlockpy = None  # type: ignore[assignment]

__all__ = [
    "IsolationPolicy",
    "IsolationSupport",
    "Limits",
    "SharedLandlock",
    "clean_environment",
    "coverable_folders",
    "enter_sandbox",
    "prepare_cgroup",
    "prime_caches",
    "probe_support",
    "readable_paths",
    "shared_landlock",
]

GIB = 1 << 30
MIB = 1 << 20

# <sched.h>: flag of unshare(2) for a new, empty network namespace (only ``lo``, down).
CLONE_NEWNET = 0x40000000
# <linux/prctl.h>: keep the permitted capabilities when setresuid() leaves uid 0.
PR_SET_KEEPCAPS = 8
# <linux/prctl.h>: remove one capability from the bounding set (needs CAP_SETPCAP);
# a process can never regain a capability that is not in its bounding set.
PR_CAPBSET_DROP = 24
# <linux/capability.h>: bypass read and search permission checks on files and
# directories. Kept because the Python installation may live under a directory
# that other users cannot enter (here /root, mode 700); Landlock still confines
# reads to the allowed paths.
CAP_DAC_READ_SEARCH = 2
# <linux/capability.h>: header version of capset(2) with two 32-bit data words.
LINUX_CAPABILITY_VERSION_3 = 0x20080522
# Highest capability number (CAP_CHECKPOINT_RESTORE, Linux 5.9+) if
# /proc/sys/kernel/cap_last_cap cannot be read.
CAP_LAST_CAP_FALLBACK = 40

# uid_t is 32 bits and (uid_t)-1 means "unchanged" to setresuid(2).
MAX_UID = 2**32 - 1

SAFE_PATH = "/usr/local/bin:/usr/bin:/bin"

# Read-only roots the child needs besides the Python installation.
SYSTEM_READ_ROOTS = (
    "/usr",
    "/lib",
    "/lib64",
    "/lib32",
    "/bin",
    "/etc",
    "/proc",
    "/sys/devices/system/cpu",
    "/usr/share/fonts",
)
# Root-only files under /etc. The child keeps CAP_DAC_READ_SEARCH, which bypasses
# their file modes, so Landlock must not allow them.
SYSTEM_SECRETS = (
    "/etc/shadow",
    "/etc/shadow-",
    "/etc/gshadow",
    "/etc/gshadow-",
    "/etc/sudoers",
    "/etc/sudoers.d",
    "/etc/ssh",
    "/etc/ssl/private",
)
# Packages of the grader itself: their sources hold the model solutions and the
# grading logic. The worker imports what it needs from ``autograder`` before forking.
HIDDEN_PACKAGES = ("reference", "autograder")


# --------------------------------------------------------------------------- policy


@dataclass(frozen=True)
class Limits:
    """Resource limits of one worker child.

    Parameters
    ----------
    memory_bytes : int
        Address space (``RLIMIT_AS``); a larger allocation raises ``MemoryError``.
    cpu_seconds : int
        CPU time (``RLIMIT_CPU``); ``SIGXCPU`` at the limit, ``SIGKILL`` one second later.
    processes : int
        Processes and threads of the child's user (``RLIMIT_NPROC``).
    open_files : int
        File descriptors (``RLIMIT_NOFILE``).
    file_size_bytes : int
        Largest file the child may write (``RLIMIT_FSIZE``).
    output_bytes : int
        Cap on captured stdout/stderr, enforced by the worker, not here.
    disk_bytes : int
        Total size of the files in the working directory (the size of the tmpfs
        mounted over it; needs a mount namespace, see :mod:`autograder.sandbox.seccomp`).
    """

    memory_bytes: int = 4 * GIB
    cpu_seconds: int = 60
    processes: int = 64
    open_files: int = 256
    file_size_bytes: int = 64 * MIB
    output_bytes: int = 1 * MIB
    disk_bytes: int = 256 * MIB

    def __post_init__(self) -> None:
        for name in ("memory_bytes", "cpu_seconds", "processes", "open_files",
                     "file_size_bytes", "output_bytes", "disk_bytes"):
            _require_positive_int(f"limits.{name}", getattr(self, name))


@dataclass(frozen=True)
class IsolationPolicy:
    """What :func:`enter_sandbox` applies.

    Parameters
    ----------
    limits : Limits
        Resource limits.
    landlock : bool
        Enforce the Landlock ruleset (files, TCP, signals) when the kernel has it.
    network_namespace : bool
        Move into an empty network namespace; applied only when running as root.
    drop_user : bool
        Switch to uid/gid ``base_uid + slot``; applied only when running as root.
    base_uid : int
        First uid of the worker slots; slot ``k`` runs as ``base_uid + k`` so that
        concurrent children never share an ``RLIMIT_NPROC`` count.
    allowed_read : tuple of str
        Extra read-only paths (for example a shared data set).
    namespaces : bool
        Private IPC, UTS and mount namespaces and the disk quota (as an ordinary
        user, inside a user namespace when the kernel allows one).
    seccomp : bool
        Load the seccomp filter of :func:`autograder.sandbox.seccomp.install_filter`.
    cgroup : bool
        As root, move the child into its slot's cgroup (equal CPU weight per slot,
        ``pids.max``, a kill that re-forking cannot dodge; see :mod:`autograder.sandbox.cgroups`).
    """

    limits: Limits = field(default_factory=Limits)
    landlock: bool = True
    network_namespace: bool = True
    drop_user: bool = True
    base_uid: int = 61000
    allowed_read: tuple[str, ...] = ()
    namespaces: bool = True
    seccomp: bool = True
    cgroup: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.limits, Limits):
            raise UsageError(
                f"`policy.limits` must be a `Limits`; got {type(self.limits).__name__}."
            )
        for name in ("landlock", "network_namespace", "drop_user", "namespaces", "seccomp",
                     "cgroup"):
            if not isinstance(getattr(self, name), bool):
                value = getattr(self, name)
                raise UsageError(f"`policy.{name}` must be True or False; got {value!r}.")
        _require_positive_int("policy.base_uid", self.base_uid)
        if isinstance(self.allowed_read, (str, bytes)) or not all(
            isinstance(p, str) for p in self.allowed_read
        ):
            raise UsageError("`policy.allowed_read` must be a tuple of path strings; "
                             f"got {self.allowed_read!r}.")
        object.__setattr__(self, "allowed_read", tuple(self.allowed_read))


def _require_positive_int(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
        raise UsageError(f"`{name}` must be a positive integer; got {value!r}.")


# -------------------------------------------------------------------------- support


@dataclass(frozen=True)
class IsolationSupport:
    """What the running kernel and user allow.

    Attributes
    ----------
    landlock_abi : int
        Landlock ABI version of the kernel, 0 when Landlock is unavailable.
    is_root : bool
        Whether the process runs as root (namespace and user switch possible).
    can_unshare_net : bool
        Whether a child could create a network namespace.
    notes : tuple of str
        One sentence per missing protection, for the grader's log.
    user_namespaces : bool
        Whether a child may create a user namespace (always True for root); an
        ordinary user gets IPC, mount and network namespaces and the disk quota
        only through one.
    seccomp : bool
        Whether libseccomp is available to build the system-call filter.
    """

    landlock_abi: int
    is_root: bool
    can_unshare_net: bool
    notes: tuple[str, ...]
    user_namespaces: bool = False
    seccomp: bool = False


@functools.cache
def probe_support() -> IsolationSupport:
    """Find out which protections this machine supports (cached per process).

    The network namespace is tried in a short-lived forked child, so the caller
    is left unchanged.

    Returns
    -------
    IsolationSupport
    """
    abi = _landlock_abi()
    is_root = os.geteuid() == 0
    can_unshare = _try_in_child(lambda: _unshare(CLONE_NEWNET))
    userns = seccomp.user_namespaces_allowed()
    has_seccomp = seccomp.pyseccomp is not None
    notes = _support_notes(abi, is_root, can_unshare) + _syscall_notes(is_root, userns, has_seccomp)
    return IsolationSupport(abi, is_root, can_unshare, notes, userns, has_seccomp)


def _syscall_notes(is_root: bool, userns: bool, seccomp: bool) -> tuple[str, ...]:
    notes = []
    if not seccomp:
        notes.append("libseccomp is missing (Debian: libseccomp2): new sockets of other "
                     "families than TCP, keyrings and memfd files are not blocked.")
    if not is_root and not userns:
        notes.append("User namespaces are refused for this user: no IPC or mount namespace "
                     "(System V IPC is blocked by seccomp instead) and no total disk quota.")
    cgroup_note = cgroups.cgroup_support()
    if not cgroup_note.startswith("cgroup v"):
        notes.append(cgroup_note)
    return tuple(notes)


def _landlock_abi() -> int:
    return 0 if landlockpy is None else landlockpy.abi_version()


def _support_notes(abi: int, is_root: bool, can_unshare: bool) -> tuple[str, ...]:
    notes = []
    if abi == 0:
        notes.append(
            "Landlock is not available (kernel ABI 0): file and network restrictions "
            "are off; rlimits, timeouts and the network namespace still apply."
        )
    elif abi < 4:
        notes.append(f"Landlock ABI {abi} has no TCP rules (needs ABI 4): only the "
                     "network namespace blocks TCP.")
    if 0 < abi < 6:
        notes.append(f"Landlock ABI {abi} cannot scope signals (needs ABI 6): only the "
                     "separate user id stops the child from signalling the grader.")
    if not is_root:
        notes.append("Not running as root: the child keeps the grader's user id (its "
                     "network, IPC and mount namespaces come from a user namespace where "
                     "allowed); RLIMIT_NPROC is set to the limit plus the user's existing tasks.")
    elif not can_unshare:
        notes.append("A network namespace cannot be created here: only Landlock "
                     "blocks TCP.")
    return tuple(notes)


def _try_in_child(action: Callable[[], object]) -> bool:
    """Run ``action`` in a forked child; True when it returned without an error."""
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            action()
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    return os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0


# ---------------------------------------------------------------------- environment


def clean_environment(workdir: Path) -> dict[str, str]:
    """Build the child's whole environment and create its temporary directory.

    Parameters
    ----------
    workdir : Path
        The submission's working directory; it becomes ``HOME``.

    Returns
    -------
    dict of str to str
        A fresh environment: nothing is copied from the grader's.
    """
    workdir = Path(workdir)
    tmpdir = workdir / ".tmp"
    tmpdir.mkdir(parents=True, exist_ok=True)
    return {
        "PATH": SAFE_PATH,
        "HOME": str(workdir),
        "TMPDIR": str(tmpdir),
        "LANG": "C.UTF-8",
        "LC_ALL": "C.UTF-8",
        "MPLBACKEND": "Agg",
        "MPLCONFIGDIR": str(workdir / ".mpl"),
        "OPENBLAS_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONHASHSEED": "0",
    }


def _replace_environment(env: dict[str, str]) -> str:
    """Install ``env`` as the only environment, and wipe the inherited one.

    ``os.environ.clear()`` unsets the variables, but the strings the process was
    started with stay in its memory and are still listed by ``/proc/self/environ``;
    after ``clearenv()`` nothing refers to them, so they are overwritten with zeros.
    :mod:`tempfile` caches its directory, possibly already in the warm parent, so
    it is pointed at the new ``TMPDIR`` as well.
    """
    os.environ.clear()
    _libc().clearenv()
    try:
        _zero_initial_environ()
    except (OSError, ValueError, IndexError) as exc:
        note = f"environment replaced; inherited block not wiped: {exc}"
    else:
        note = "environment replaced, inherited block wiped"
    os.environ.update(env)
    tempfile.tempdir = env["TMPDIR"]
    return note


def _zero_initial_environ() -> None:
    """Overwrite the block shown by ``/proc/self/environ`` (fields 50-51 of stat)."""
    stat = Path("/proc/self/stat").read_text()
    fields = stat.rsplit(")", 1)[1].split()  # fields[0] is field 3 ("state")
    start, end = int(fields[50 - 3]), int(fields[51 - 3])
    if not 0 < start < end:
        raise ValueError("/proc/self/stat hides the environment's addresses")
    ctypes.memset(start, 0, end - start)


# ----------------------------------------------------------------------- read paths


def readable_paths(exclude: Sequence[Path], *, extra: Sequence[Path] = ()) -> list[Path]:
    """Read-only roots the child needs, with the grader's own files left out.

    A root that contains an excluded path is replaced by its entries, one level at
    a time down to the excluded path (site-packages thus becomes one rule per
    entry), so that no allowed rule covers anything excluded.

    Parameters
    ----------
    exclude : sequence of Path
        Trees the child must not read: the repository root and the assignment folder.
        The ``reference`` and ``autograder`` packages, their ``*.dist-info`` and the
        ``__editable__*`` files of site-packages are always excluded.
    extra : sequence of Path
        More roots to allow (``IsolationPolicy.allowed_read``).

    Returns
    -------
    list of Path
        Resolved, existing paths; none inside another, none covering an excluded path.
    """
    return list(_readable_paths_cached(tuple(map(str, exclude)), tuple(map(str, extra))))


def prime_caches() -> None:
    """Fill the caches every request needs, whatever it excludes.

    The warm parent calls it while it starts, so its first submission does not pay
    for listing the installed distributions and walking the readable roots (about
    0.3 s of CPU); what depends on a request's exclusions is computed at its first
    spawn.
    """
    _hidden_installed_paths()
    readable_paths([])


@functools.lru_cache(maxsize=16)
def _readable_paths_cached(exclude: tuple[str, ...], extra: tuple[str, ...]) -> tuple[Path, ...]:
    # Walking site-packages costs tens of milliseconds; the warm parent computes the
    # list once and every forked child inherits the cache (sys.path is fixed by then).
    holes = {_resolve(p) for p in exclude}
    holes.update(_hidden_installed_paths(), map(Path, SYSTEM_SECRETS))
    roots = _outermost([root for root in _candidate_roots([Path(e) for e in extra]) if root.exists()])
    seen: set[Path] = set()
    return tuple(_outermost([path for root in roots
                             for path in _allowed_beneath(root, holes, seen)]))


def _candidate_roots(extra: Sequence[Path]) -> list[Path]:
    """What Python needs, wherever it lies: the installation, its site-packages, the system.

    Only directories that belong to the interpreter are taken from ``sys.path``
    (site-packages and anything inside the installation or the venv); the current
    folder, a course folder or a repository on the grader's path are not, since
    they may hold other students' files, checks or model solutions.
    """
    paths = sysconfig.get_paths()
    python = [sys.prefix, sys.base_prefix, sys.exec_prefix, sys.base_exec_prefix,
              paths["stdlib"], paths["platstdlib"], paths["purelib"], paths["platlib"],
              os.path.dirname(os.path.realpath(sys.executable))]
    installs = [_resolve(p) for p in python]
    on_path = [Path(entry) for entry in sys.path if entry and os.path.isabs(entry)]
    site_dirs = [path for path in on_path
                 if path.name in ("site-packages", "dist-packages")
                 or any(_within(_resolve(path), root) for root in installs)]
    return [_resolve(p) for p in [*installs, *_site_packages_dirs(), *site_dirs,
                                  *SYSTEM_READ_ROOTS, *extra]]


def _allowed_beneath(root: Path, holes: set[Path], seen: set[Path]) -> Iterator[Path]:
    """Yield ``root`` if it holds no hole, else its entries that hold none (recursively).

    A hole *around* a root does not take the root away: a venv inside the
    repository (``.venv``), or under ``/autograder`` next to the results, stays
    readable while the rest of the repository or results folder does not.
    """
    if root in seen or root in holes:
        return
    seen.add(root)
    inner = {hole for hole in holes if hole != root and _within(hole, root)}
    if not inner:
        yield root
        return
    try:
        entries = sorted(root.iterdir())
    except OSError:  # unreadable here, hence not needed by the child either
        return
    for entry in entries:
        # A link inside an allowed directory grants nothing beyond it (Landlock
        # follows inodes), so links are not followed here either.
        if not entry.is_symlink():
            yield from _allowed_beneath(entry, inner, seen)


def _within(path: Path, root: Path) -> bool:
    """Whether ``path`` is ``root`` or lies beneath it, comparing components.

    The same answer as ``path == root or root in path.parents`` (or
    ``path.is_relative_to(root)``) for the absolute, resolved paths used here,
    without building a ``Path`` per parent or raising per miss: the warm parent
    asks this about 10^5 times when it lists the readable paths, on the way to its
    first child (measured: 0.2 s of CPU with ``parents``, 0.035 s like this).
    """
    prefix = root.parts
    return path.parts[:len(prefix)] == prefix


def _outermost(paths: Sequence[Path]) -> list[Path]:
    """Drop duplicates and paths that lie inside another path of the list."""
    kept: list[Path] = []
    kept_parts: set[tuple[str, ...]] = set()
    for path in sorted(set(paths), key=lambda p: len(p.parts)):
        parts = path.parts
        if not any(parts[:end] in kept_parts for end in range(1, len(parts) + 1)):
            kept.append(path)
            kept_parts.add(parts)
    return sorted(kept)


@functools.cache
def _hidden_installed_paths() -> tuple[Path, ...]:
    """Directories of the grader's packages and their install records in site-packages.

    Cached: the worker's warm parent can call :func:`readable_paths` once before
    forking so that children do not scan the installed distributions again.
    """
    hidden = [Path(d) for name in HIDDEN_PACKAGES for d in _package_dirs(name)]
    dists = _distribution_names(HIDDEN_PACKAGES)
    for directory in _site_packages_dirs():
        hidden += [entry for entry in directory.iterdir() if _is_install_record(entry.name, dists)]
    return tuple(_resolve(p) for p in hidden)


def _package_dirs(name: str) -> list[str]:
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return []
    if spec is None:
        return []
    locations = list(spec.submodule_search_locations or [spec.origin or ""])
    return [path for path in locations if os.path.isabs(path)]  # not editable placeholders


def _distribution_names(packages: Sequence[str]) -> set[str]:
    """Normalised names of the distributions that install ``packages``.

    A distribution installs a package when its ``top_level.txt`` names it or,
    without that file, when a ``.py`` file it lists lies in the package's folder
    or is the module itself: what ``importlib.metadata.packages_distributions()``
    answers on Python 3.11, without its price. That parses the file list of every
    distribution without ``top_level.txt`` (0.13 s of CPU with 200 installed, on
    the warm parent's way to its first child); a list that does not even contain
    a package's name cannot place a file in it, so only the others are parsed.
    """
    wanted = set(packages)
    names: set[str] = set()
    for dist in importlib.metadata.distributions():
        declared = (dist.read_text("top_level.txt") or "").split()
        if declared:
            tops = set(declared)
        elif any(name in (dist.read_text(listing) or "")
                 for listing in ("RECORD", "installed-files.txt", "SOURCES.txt")
                 for name in wanted):
            tops = {f.parts[0] if len(f.parts) > 1 else f.with_suffix("").name
                    for f in dist.files or () if f.suffix == ".py"}
        else:
            continue
        name = dist.metadata["Name"]
        if tops & wanted and name:
            names.add(_normalise(name))
    return names


def _is_install_record(entry: str, dists: set[str]) -> bool:
    if entry.startswith("__editable__"):
        return True
    stem, dot, suffix = entry.rpartition(".")
    if suffix not in ("dist-info", "egg-info", "egg-link") or not dot:
        return False
    return _normalise(stem.split("-")[0]) in dists


def _normalise(name: str) -> str:
    return name.lower().replace("-", "_").replace(".", "_")


def _site_packages_dirs() -> list[Path]:
    candidates = [*site.getsitepackages(), site.getusersitepackages(),
                  sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    names = {"site-packages", "dist-packages"}
    candidates += [p for p in sys.path if os.path.basename(p) in names]
    return [path for path in {_resolve(p) for p in candidates} if path.is_dir()]


def _resolve(path: str | os.PathLike[str]) -> Path:
    return Path(path).resolve()


# --------------------------------------------------------------------------- entry


def enter_sandbox(
    policy: IsolationPolicy,
    workdir: Path,
    *,
    slot: int,
    exclude: Sequence[Path] = (),
    shared: SharedLandlock | None = None,
) -> tuple[str, ...]:
    """Confine the calling process; call it in the forked child, before student code.

    Parameters
    ----------
    policy : IsolationPolicy
        What to apply.
    workdir : Path
        The submission's directory: the only place the child may write.
    slot : int
        Index of the worker slot; the child runs as ``policy.base_uid + slot``.
    exclude : sequence of Path
        Trees the child must not read (repository root, assignment folder).
    shared : SharedLandlock, optional
        The Landlock ruleset the warm parent built once (see :func:`shared_landlock`),
        used when ``workdir`` lies directly in its work root; the child then adds a
        small layer of its own that confines writes to ``workdir``. Without it the
        child builds the whole ruleset itself.

    Returns
    -------
    tuple of str
        One short note per step, saying what was applied or why it was skipped.

    Raises
    ------
    UsageError
        If ``slot`` is not a non-negative integer or ``workdir`` is not a directory.
    OSError
        If a resource limit cannot be set: the limits are the floor of the sandbox.

    Notes
    -----
    Must run in a single-threaded process (a fresh fork): Landlock before ABI 8
    restricts only the calling thread. A step the environment refuses (for example
    ``EPERM`` in an unprivileged container) is skipped and noted, never raised.
    """
    workdir = _check_arguments(policy, workdir, slot)
    notes: list[str] = []
    _attempt(notes, "new session", os.setsid)
    private_ipc = _apply_namespaces(policy, workdir, exclude, notes)
    notes.append(_replace_environment(clean_environment(workdir)))
    os.chdir(workdir)
    if shared is not None and shared.serves(policy, workdir, exclude):
        notes.extend(shared.notes)
        ruleset = shared.ruleset
        writes = None if ruleset is None else _write_layer(workdir, notes)
    else:
        ruleset, writes = _prepare_landlock(policy, workdir, exclude, notes), None
    notes.append(_apply_limits(policy.limits, _process_allowance(policy)))
    _join_cgroup(policy, slot, notes)
    _apply_identity(policy, workdir, policy.base_uid + slot, notes)
    if policy.seccomp:
        _attempt(notes, "seccomp", lambda: seccomp.install_filter(block_sysv_ipc=not private_ipc))
    else:
        notes.append("seccomp off by policy")
    if ruleset is not None:
        _attempt(notes, "landlock", lambda: _restrict(ruleset))
    if writes is not None:
        _attempt(notes, "landlock write layer",
                 lambda: _restrict(writes, "landlock write layer"))
    return tuple(notes)


def _apply_namespaces(policy: IsolationPolicy, workdir: Path, exclude: Sequence[Path],
                      notes: list[str]) -> bool:
    """Private IPC/UTS/mount namespaces and the disk quota; True if IPC is private.

    An ordinary user also gets an empty network namespace here, inside the same
    user namespace (root gets one in :func:`_apply_identity`). Excluded folders
    that hold nothing the child needs are covered by empty mounts.
    """
    if not policy.namespaces:
        notes.append("IPC/mount namespaces and disk quota off by policy")
        return False
    result = seccomp.private_namespaces(
        workdir, quota_bytes=policy.limits.disk_bytes,
        network=policy.network_namespace and os.geteuid() != 0,
        hide=coverable_folders(exclude, workdir, policy))
    notes.extend(result.notes)
    return result.ipc


def coverable_folders(exclude: Sequence[Path], workdir: Path,
                      policy: IsolationPolicy) -> tuple[Path, ...]:
    """The excluded folders an empty mount may cover in the child.

    Only folders outside every readable root (so not a forbidden library inside
    site-packages, which Landlock alone keeps out) and holding neither a readable
    root (a venv inside the repository) nor the working directory; none inside
    another. The warm parent computes this once (cached) before it forks.
    """
    return _coverable_for(tuple(map(str, exclude)), str(workdir), policy.allowed_read)


@functools.lru_cache(maxsize=32)
def _coverable_for(exclude: tuple[str, ...], workdir: str,
                   allowed: tuple[str, ...]) -> tuple[Path, ...]:
    # Cached too: the warm parent's call for a request fills it for the child it forks.
    work = _resolve(workdir)
    found: list[Path] = []
    for folder in _coverable(exclude, allowed):
        if not _within(work, folder) and not any(_within(folder, f) for f in found):
            found.append(folder)
    return tuple(found)


@functools.lru_cache(maxsize=32)
def _coverable(exclude: tuple[str, ...], allowed: tuple[str, ...]) -> tuple[Path, ...]:
    """The excluded folders outside every root and holding none, shortest first."""
    extra = [Path(p) for p in allowed]
    whole = readable_paths([], extra=extra)  # the roots before any hole is cut
    needed = [*whole, *readable_paths([Path(p) for p in exclude], extra=extra)]
    return tuple(
        folder for folder in sorted({_resolve(p) for p in exclude}, key=lambda p: len(p.parts))
        if folder.is_dir() and folder != Path("/")
        and not any(_within(folder, root) for root in whole)
        and not any(_within(path, folder) for path in needed))


def _join_cgroup(policy: IsolationPolicy, slot: int, notes: list[str]) -> None:
    """As root, enter the slot's cgroup (before the user switch: it needs root)."""
    if not policy.cgroup or os.geteuid() != 0:
        notes.append("slot cgroup " + ("off by policy" if not policy.cgroup
                                       else "skipped: not running as root"))
        return
    group = cgroups.slot_cgroup(slot, processes=policy.limits.processes)
    if group is None:
        notes.append("slot cgroup skipped: no usable cgroup hierarchy")
        return
    _attempt(notes, "slot cgroup", lambda: _join(group, slot, policy.limits.processes))


def prepare_cgroup(policy: IsolationPolicy, slot: int) -> None:
    """Make and configure the slot's cgroup in the warm parent, once, before it forks.

    Every child then only joins it (see :func:`_join_cgroup`); nothing happens for
    an ordinary user or a policy without cgroups.
    """
    if policy.cgroup and os.geteuid() == 0:
        cgroups.slot_cgroup(slot, processes=policy.limits.processes)


#: as root, the network namespace the warm parent came from (an open descriptor), once
#: :func:`prepare_network` moved it into the empty one its children share
_HOST_NETWORK: list[int | None] = [None]


def prepare_network(policy: IsolationPolicy) -> None:
    """As root, move the warm parent into an empty network namespace, once, before it forks.

    Every child is then born in it and needs no ``unshare`` of its own: about 0.5 ms
    of the child's CPU and 1 ms of the kernel's teardown per submission
    (``benchmarks/sandbox_costs.py``). Sharing it leaks nothing from one student to the
    next: a slot runs one child at a time, every process of a submission is killed
    before the next starts (:func:`autograder.engine.slot.sweep_slot`), and no child keeps
    the capabilities to configure the namespace (only ``lo``, down). A child whose
    policy wants the network returns to the namespace the parent came from. Nothing
    happens for an ordinary user, whose children make their own inside a user namespace.
    """
    if not policy.network_namespace or os.geteuid() != 0 or _HOST_NETWORK[0] is not None:
        return
    try:
        host = os.open("/proc/self/ns/net", os.O_RDONLY | os.O_CLOEXEC)
    except OSError:  # no /proc: each child unshares its own
        return
    try:
        _unshare(CLONE_NEWNET)
    except OSError:
        os.close(host)
        return
    _HOST_NETWORK[0] = host


def _network(policy: IsolationPolicy, notes: list[str]) -> None:
    """As root, in the child: the empty network namespace, or the host's if the policy says."""
    host, _HOST_NETWORK[0] = _HOST_NETWORK[0], None
    if host is None:
        if policy.network_namespace:
            _attempt(notes, "network namespace", lambda: _unshare(CLONE_NEWNET))
        else:
            notes.append("network namespace off by policy")
        return
    try:  # the child keeps no handle on the host's namespace
        if policy.network_namespace:
            notes.append("network namespace: the slot's empty one (made once by the warm parent)")
        else:
            _attempt(notes, "network namespace off by policy, host network restored",
                     lambda: _setns(host, CLONE_NEWNET))
    finally:
        os.close(host)


def _join(group: cgroups.SlotCgroup, slot: int, processes: int) -> str:
    try:
        group.join()
    except FileNotFoundError:  # removed since the warm parent made it: make it again
        cgroups.forget_created()
        group = cgroups.slot_cgroup(slot, processes=processes) or group
        group.join()
    return f"slot cgroup v{group.version}: {', '.join(str(d) for d in group.dirs)}"


def _check_arguments(policy: IsolationPolicy, workdir: Path, slot: int) -> Path:
    if isinstance(slot, bool) or not isinstance(slot, int) or slot < 0:
        raise UsageError(f"`slot` must be a non-negative integer; got {slot!r}.")
    if policy.base_uid + slot >= MAX_UID:
        raise UsageError(f"`policy.base_uid + slot` must be below {MAX_UID}; "
                         f"got {policy.base_uid + slot}.")
    resolved = _resolve(workdir)
    if not resolved.is_dir():
        raise UsageError(f"`workdir` must be an existing directory; got {str(workdir)!r}.")
    return resolved


def _attempt(notes: list[str], label: str, step: Callable[[], str | None]) -> None:
    """Run one step; note its result, or note and skip it if the system refuses."""
    try:
        result = step()
    except OSError as exc:
        notes.append(f"{label} skipped: {exc.strerror or exc}")
    else:
        notes.append(result or label)


# -------------------------------------------------------------------------- rlimits


def _apply_limits(limits: Limits, processes: int) -> str:
    """Set every rlimit with soft = hard so the child cannot raise it back.

    The CPU hard limit is one second above the soft one: ``SIGXCPU`` first (a
    catchable warning), then ``SIGKILL``.
    """
    wanted = [
        ("RLIMIT_AS", resource.RLIMIT_AS, limits.memory_bytes, limits.memory_bytes),
        ("RLIMIT_CPU", resource.RLIMIT_CPU, limits.cpu_seconds, limits.cpu_seconds + 1),
        ("RLIMIT_NPROC", resource.RLIMIT_NPROC, processes, processes),
        ("RLIMIT_NOFILE", resource.RLIMIT_NOFILE, limits.open_files, limits.open_files),
        ("RLIMIT_FSIZE", resource.RLIMIT_FSIZE, limits.file_size_bytes, limits.file_size_bytes),
        ("RLIMIT_CORE", resource.RLIMIT_CORE, 0, 0),
    ]
    for name, which, soft, hard in wanted:
        _set_limit(name, which, soft, hard)
    return "rlimits: " + ", ".join(f"{name[7:].lower()}={soft}" for name, _, soft, _ in wanted)


def _set_limit(name: str, which: int, soft: int, hard: int) -> None:
    """Lower a limit; never above the current hard limit (raising needs privileges)."""
    current_hard = resource.getrlimit(which)[1]
    if current_hard != resource.RLIM_INFINITY:
        soft, hard = min(soft, current_hard), min(hard, current_hard)
    try:
        resource.setrlimit(which, (soft, hard))
    except (OSError, ValueError) as exc:
        code = getattr(exc, "errno", None) or errno.EPERM
        raise OSError(code, f"could not set {name} to {soft}/{hard}: {exc}") from exc


def _process_allowance(policy: IsolationPolicy) -> int:
    """RLIMIT_NPROC counts every task of the real uid, not only the child's.

    When the child gets a uid of its own the count starts at zero; otherwise the
    user's existing processes and threads are added to the limit.
    """
    if os.geteuid() == 0 and policy.drop_user:
        return policy.limits.processes
    return policy.limits.processes + _count_tasks(os.getuid())


def _count_tasks(uid: int) -> int:
    total = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            status = Path(entry.path, "status").read_text()
        except OSError:  # the process exited meanwhile
            continue
        fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
        if int(fields["Uid"].split()[0]) == uid:
            total += int(fields["Threads"])
    return total


# ---------------------------------------------------------- namespace, user and caps


def _apply_identity(policy: IsolationPolicy, workdir: Path, uid: int, notes: list[str]) -> None:
    """As root: an empty network namespace, then a user id of the slot's own."""
    if os.geteuid() != 0:
        notes.append("user switch skipped: not running as root (a network namespace only inside a "
                     "user namespace, see the namespaces note)")
        return
    _network(policy, notes)
    if policy.drop_user:
        _attempt(notes, "user switch", lambda: _drop_user(workdir, uid))
    else:
        notes.append("user switch off: RLIMIT_NPROC does not bind root")


def _drop_user(workdir: Path, uid: int) -> str:
    """Become ``uid``/``uid`` with CAP_DAC_READ_SEARCH as the only capability."""
    _chown_tree(workdir, uid)
    _drop_bounding_set(keep=CAP_DAC_READ_SEARCH)
    _prctl(PR_SET_KEEPCAPS, 1)  # else setresuid() below clears the permitted set
    os.setgroups([])
    os.setresgid(uid, uid, uid)
    os.setresuid(uid, uid, uid)
    _capset(1 << CAP_DAC_READ_SEARCH)
    return f"user: uid and gid {uid}, no groups, capabilities: CAP_DAC_READ_SEARCH"


def _chown_tree(top: Path, uid: int) -> None:
    """Give the working directory to the child's user (links are not followed)."""
    os.chown(top, uid, uid, follow_symlinks=False)
    for directory, subdirs, files in os.walk(top):
        for name in subdirs + files:
            os.chown(os.path.join(directory, name), uid, uid, follow_symlinks=False)


def _drop_bounding_set(*, keep: int) -> None:
    for cap in range(_last_capability() + 1):
        if cap != keep:
            _prctl(PR_CAPBSET_DROP, cap)


def _last_capability() -> int:
    try:
        return int(Path("/proc/sys/kernel/cap_last_cap").read_text())
    except (OSError, ValueError):
        return CAP_LAST_CAP_FALLBACK


class _CapHeader(ctypes.Structure):
    """struct __user_cap_header_struct of <linux/capability.h>."""

    _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]


class _CapData(ctypes.Structure):
    """struct __user_cap_data_struct: one 32-bit word of each capability set."""

    _fields_ = [
        ("effective", ctypes.c_uint32),
        ("permitted", ctypes.c_uint32),
        ("inheritable", ctypes.c_uint32),
    ]


def _capset(mask: int) -> None:
    """Set effective = permitted = ``mask`` and inheritable = 0 for this thread."""
    header = _CapHeader(LINUX_CAPABILITY_VERSION_3, 0)
    data = (_CapData * 2)()
    for word in range(2):
        bits = (mask >> (32 * word)) & 0xFFFFFFFF
        data[word].effective = data[word].permitted = bits
    _check_libc("capset", _libc().capset(ctypes.byref(header), data))


def _unshare(flags: int) -> None:
    # Python 3.11 has no os.unshare (added in 3.12).
    _check_libc("unshare", _libc().unshare(flags))


def _setns(fd: int, kind: int) -> None:
    # Python 3.11 has no os.setns (added in 3.12).
    _check_libc("setns", _libc().setns(fd, kind))


def _prctl(option: int, arg: int) -> None:
    # prctl(2) is variadic: pass every argument as a full unsigned long.
    args = [ctypes.c_ulong(value) for value in (arg, 0, 0, 0)]
    _check_libc("prctl", _libc().prctl(ctypes.c_int(option), *args))


@functools.cache
def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def _check_libc(name: str, result: int) -> None:
    if result == -1:
        code = ctypes.get_errno()
        raise OSError(code, f"{name}: {os.strerror(code)}")


# ------------------------------------------------------------------------- landlock


def _prepare_landlock(
    policy: IsolationPolicy, workdir: Path, exclude: Sequence[Path], notes: list[str]
) -> Ruleset | None:
    """Build the ruleset while the paths can still be opened; enforced at the end."""
    if not policy.landlock:
        notes.append("landlock off by policy")
        return None
    abi = _landlock_abi()
    if abi == 0:
        notes.append("landlock skipped: not available (kernel ABI 0)")
        return None
    roots = readable_paths(exclude, extra=[Path(p) for p in policy.allowed_read])
    try:
        return _build_ruleset(abi, workdir, roots, notes)
    except OSError as exc:
        notes.append(f"landlock skipped: {exc.strerror or exc}")
        return None


@dataclass(frozen=True)
class SharedLandlock:
    """The Landlock ruleset a warm parent builds once and every child it forks enforces.

    Building the whole ruleset costs a child several milliseconds (one rule per
    readable root, hundreds of them); built once before any fork, each child only
    enforces the inherited descriptor. Its only writable folder is the slot's *work
    root*, the parent of every submission's working directory; a second, small layer
    that each child adds (:func:`_write_layer`) narrows writing to its own working
    directory, as Landlock layers intersect. The grader puts nothing else in the work
    root while a child runs.
    """

    ruleset: Ruleset | None
    work_root: Path
    notes: tuple[str, ...]
    #: the policy's file and folder settings and the exclusions it was built for
    key: tuple[object, ...]

    def serves(self, policy: IsolationPolicy, workdir: Path, exclude: Sequence[Path]) -> bool:
        """Whether this ruleset is the one ``policy`` asks for a child in ``workdir``."""
        return (_resolve(workdir).parent == self.work_root
                and self.key == _landlock_key(policy, self.work_root, exclude))

    def close(self) -> None:
        if self.ruleset is not None:
            self.ruleset.close()


def shared_landlock(policy: IsolationPolicy, work_root: Path,
                    exclude: Sequence[Path]) -> SharedLandlock:
    """Build the ruleset for every child whose working directory is in ``work_root``.

    Call it in the warm parent, before forking; the ruleset's descriptor is inherited
    and closed by each child as it enforces it.
    """
    work_root = _resolve(work_root)
    notes: list[str] = []
    ruleset = _prepare_landlock(policy, work_root, exclude, notes)
    return SharedLandlock(ruleset, work_root, tuple(notes),
                          _landlock_key(policy, work_root, exclude))


def _landlock_key(policy: IsolationPolicy, work_root: Path,
                  exclude: Sequence[Path]) -> tuple[object, ...]:
    return (policy.landlock, tuple(policy.allowed_read), str(work_root),
            _resolved_sorted(tuple(map(str, exclude))))


@functools.lru_cache(maxsize=32)
def _resolved_sorted(paths: tuple[str, ...]) -> tuple[str, ...]:
    # Cached: the warm parent resolves a request's exclusions, the child it forks reuses them.
    return tuple(sorted(str(_resolve(p)) for p in paths))


def _write_layer(workdir: Path, notes: list[str]) -> Ruleset | None:
    """A ruleset that handles only the rights to change files and allows them in
    ``workdir`` and the writable devices; enforced on top of the shared ruleset."""
    handled = landlockpy.fs_for_abi(_landlock_abi()) & ~_READ_RIGHTS
    try:
        ruleset = Ruleset(handled_fs=handled, handled_net=AccessNet(0))
        rules = [(workdir, _workdir_access())] + [
            (path, access) for path, access in _device_rules() if access & ~_READ_RIGHTS]
        failed = [str(path) for path, access in rules
                  if not _allow(ruleset, path, access & handled)]
    except OSError as exc:
        notes.append(f"landlock write layer skipped: {exc.strerror or exc}")
        return None
    if failed:
        notes.append(f"landlock write layer: {len(failed)} paths could not be allowed, "
                     f"e.g. {failed[0]}")
    return ruleset


def _build_ruleset(abi: int, workdir: Path, roots: Sequence[Path], notes: list[str]) -> Ruleset:
    rules = [(root, _READ_RIGHTS) for root in roots] + list(_device_rules()) + [
        (workdir, _workdir_access())
    ]
    ruleset = Ruleset(
        handled_fs=landlockpy.fs_for_abi(abi),
        handled_net=AccessNet.BIND_TCP | AccessNet.CONNECT_TCP,  # no port is allowed
        scoped=Scope.SIGNAL | Scope.ABSTRACT_UNIX_SOCKET,
    )
    failed = [str(path) for path, access in rules if not _allow(ruleset, path, access)]
    if failed:
        notes.append(f"landlock: {len(failed)} paths could not be allowed, e.g. {failed[0]}")
    return ruleset


def _workdir_access() -> AccessFS:
    """Everything a program does with its own files; no exec, devices or sockets."""
    return (AccessFS.READ_FILE | AccessFS.READ_DIR | AccessFS.WRITE_FILE | AccessFS.TRUNCATE
            | AccessFS.MAKE_REG | AccessFS.MAKE_DIR | AccessFS.MAKE_SYM | AccessFS.MAKE_FIFO
            | AccessFS.REMOVE_FILE | AccessFS.REMOVE_DIR | AccessFS.REFER)


def _device_rules() -> Iterator[tuple[Path, AccessFS]]:
    read = AccessFS.READ_FILE
    write = AccessFS.READ_FILE | AccessFS.WRITE_FILE | AccessFS.TRUNCATE
    yield from [(Path("/dev/null"), write), (Path("/dev/zero"), write),
                (Path("/dev/urandom"), read), (Path("/dev/random"), read)]


def _allow(ruleset: Ruleset, path: Path, access: AccessFS) -> bool:
    """Add one rule; False if the path cannot be opened (vanished, not permitted)."""
    if not path.is_dir():  # Landlock refuses directory rights on a single file
        access &= (AccessFS.EXECUTE | AccessFS.READ_FILE | AccessFS.WRITE_FILE
                   | AccessFS.TRUNCATE | AccessFS.IOCTL_DEV)
    try:
        ruleset.allow_path(path, access)
    except OSError:
        return False
    return True


def _restrict(ruleset: Ruleset, label: str = "landlock") -> str:
    # TSYNC (ABI 8) also restricts other threads; dropped on older kernels.
    with ruleset:
        ruleset.restrict(RestrictFlag.TSYNC)
        return (f"{label}: ABI {ruleset.abi_version}, fs {int(ruleset.handled_fs):#x}, "
                f"net {int(ruleset.handled_net):#x}, scoped {int(ruleset.scoped):#x}")
