"""Which paths the worker child may read, and which excluded folders it may not even see.

The child may read the Python installation, its site-packages and the system
directories, never the grader's own files: the packages holding the model solutions
and the grading logic, their install records, the repository and the assignment
folder, and the root-only files under ``/etc``. :func:`readable_paths` lists the
read-only roots with those left out (Landlock allows them,
:mod:`autograder.sandbox.landlock`); :func:`coverable_folders` names the excluded
folders an empty mount may cover in the child's mount namespace. Both are cached,
so the warm parent computes them once and every child it forks inherits them.
"""

from __future__ import annotations

import functools
import importlib.metadata
import importlib.util
import os
import site
import sys
import sysconfig
from collections.abc import Iterator, Sequence
from pathlib import Path

from autograder.sandbox.policy import IsolationPolicy

__all__ = ["HIDDEN_PACKAGES", "SYSTEM_READ_ROOTS", "SYSTEM_SECRETS", "coverable_folders",
           "prime_caches", "readable_paths"]

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
    wider = tuple(map(str, extra))
    return list(_readable_paths_cached(holes_that_matter(exclude, extra=extra), wider))


def holes_that_matter(exclude: Sequence[Path], *, extra: Sequence[Path] = ()) -> tuple[str, ...]:
    """The resolved paths of ``exclude`` that lie in a readable root, sorted.

    Only these change :func:`readable_paths`: a root is split around an excluded
    path inside it and dropped when it is one, but an excluded path outside every
    root (a submission's own folder in a batch, say) leaves every root as it is.
    So the answer, and a Landlock ruleset built from it, can be reused for every
    submission whose exclusions differ only there.
    """
    return _holes_that_matter(tuple(map(str, exclude)), tuple(map(str, extra)))


@functools.lru_cache(maxsize=32)
def _holes_that_matter(exclude: tuple[str, ...], extra: tuple[str, ...]) -> tuple[str, ...]:
    roots = _roots(extra)
    return tuple(sorted({str(hole) for hole in map(_resolve, exclude)
                         if any(_within(hole, root) for root in roots)}))


@functools.lru_cache(maxsize=16)
def _roots(extra: tuple[str, ...]) -> tuple[Path, ...]:
    """The readable roots before any hole is cut (sys.path is fixed once this is asked)."""
    return tuple(_outermost([root for root in _candidate_roots([Path(e) for e in extra])
                             if root.exists()]))


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
    roots = _roots(extra)
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
        if not tops & wanted:  # before the name: reading it parses the whole METADATA file
            continue
        name = dist.metadata["Name"]
        if name:
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
