"""The Landlock ruleset of a worker child: what it may read, where it may write, no TCP.

Read-only access to the readable roots (:mod:`autograder.sandbox.readable`) and a
few devices, full access to the working directory only, no TCP bind or connect,
and no signals or abstract UNIX sockets outside the sandbox. The warm parent builds
the ruleset once for every child (:func:`shared_landlock`); a child enforces it
last, with a small layer of its own on top that narrows writing to its working
directory (:func:`write_layer`). ``landlockpy`` wraps the Landlock system calls.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from autograder.sandbox.policy import IsolationPolicy
from autograder.sandbox.readable import holes_that_matter, readable_paths

try:  # Landlock is Linux-only; elsewhere the sandbox notes its absence.
    import landlockpy
    from landlockpy import AccessFS, AccessNet, RestrictFlag, Ruleset, Scope

    #: what the child may do in a readable root (everything else is about changing files)
    _READ_RIGHTS = AccessFS.READ_FILE | AccessFS.READ_DIR | AccessFS.EXECUTE
except ImportError:  # pragma: no cover - landlockpy is a Linux dependency
    landlockpy = None  # type: ignore[assignment]

__all__ = ["SharedLandlock", "allow_own_proc", "landlock_abi", "prepare_landlock", "restrict", "shared_landlock",
           "write_layer"]


def landlock_abi() -> int:
    """The kernel's Landlock ABI version, 0 when Landlock is unavailable."""
    return 0 if landlockpy is None else landlockpy.abi_version()


def prepare_landlock(
    policy: IsolationPolicy, workdir: Path, exclude: Sequence[Path], notes: list[str]
) -> Ruleset | None:
    """Build the ruleset while the paths can still be opened; enforced at the end."""
    if not policy.landlock:
        notes.append("landlock off by policy")
        return None
    abi = landlock_abi()
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
    that each child adds (:func:`write_layer`) narrows writing to its own working
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
        return (Path(workdir).resolve().parent == self.work_root
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
    work_root = Path(work_root).resolve()
    notes: list[str] = []
    ruleset = prepare_landlock(policy, work_root, exclude, notes)
    return SharedLandlock(ruleset, work_root, tuple(notes),
                          _landlock_key(policy, work_root, exclude))


def _landlock_key(policy: IsolationPolicy, work_root: Path,
                  exclude: Sequence[Path]) -> tuple[object, ...]:
    # Only the exclusions that change the readable roots change the ruleset: a batch's
    # submissions, each excluding its own folder, share one (cached: the warm parent
    # resolves a request's exclusions, the child it forks reuses them).
    extra = [Path(p) for p in policy.allowed_read]
    return (policy.landlock, tuple(policy.allowed_read), str(work_root),
            holes_that_matter(exclude, extra=extra))


def allow_own_proc(ruleset: Ruleset) -> None:
    """Let the child read the ``/proc`` it mounted for its PID namespace.

    The shared ruleset's rule for ``/proc`` names the warm parent's ``/proc``; a new
    mount over it is another file system, which Landlock does not find under that
    rule (it skips covered mount points). So the child adds a rule to the shared
    ruleset before enforcing it. The ruleset is the warm parent's own object, which
    thus keeps one rule per child for a ``/proc`` that is gone with the child's
    namespace (about a hundred bytes each): it grants nothing anyone can reach.
    """
    _allow(ruleset, Path("/proc"), _READ_RIGHTS)


def write_layer(workdir: Path, notes: list[str]) -> Ruleset | None:
    """A ruleset that handles only the rights to change files and allows them in
    ``workdir`` and the writable devices; enforced on top of the shared ruleset."""
    handled = landlockpy.fs_for_abi(landlock_abi()) & ~_READ_RIGHTS
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


def restrict(ruleset: Ruleset, label: str = "landlock") -> str:
    # TSYNC (ABI 8) also restricts other threads; dropped on older kernels.
    with ruleset:
        ruleset.restrict(RestrictFlag.TSYNC)
        return (f"{label}: ABI {ruleset.abi_version}, fs {int(ruleset.handled_fs):#x}, "
                f"net {int(ruleset.handled_net):#x}, scoped {int(ruleset.scoped):#x}")
