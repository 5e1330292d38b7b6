"""Load an assignment folder (``assignment.toml``, notebook, data, checks).

An assignment folder looks like this (see ``docs/design.md``)::

    hull/
      assignment.toml
      hull.ipynb              instructor notebook (nbgrader format)
      data/...                public data files, selected by globs
      checks/public/test_*.py released to students
      checks/hidden/test_*.py never released

``assignment.toml`` has three tables, all keys optional except that the
notebook, at least one check and every data glob must exist::

    [assignment]
    name = "hull"                 # default: the folder name
    title = "Convex hull"         # default: the name
    notebook = "hull.ipynb"       # default: "<name>.ipynb"
    data = ["data/*.npy"]         # globs relative to the folder

    [rules]
    forbid = ["scipy.spatial"]
    reason = "Write Jarvis march yourself."

    [limits]
    notebook_timeout = 60         # seconds for the whole notebook
    call_timeout = 10             # seconds per call from a check
    memory_bytes = 2_000_000_000  # and the other fields of autograder.sandbox.policy.Limits

An nbgrader source folder (no ``assignment.toml``; notebooks with nbgrader cell
metadata) loads too, through :mod:`autograder.engine.nbgrader_source`: all its
notebooks, its other files as data, its test cells and manually graded cells.
``[assignment] format = "nbgrader"`` reads a folder with a toml the same way, the
toml adding pytest checks; ``notebook`` then names the notebook the checks call.
Names are looked up under ``assignments/``, or under ``source/`` of an nbgrader
course root (``nbgrader_config.py`` beside ``source/``).

Every mistake raises :class:`~autograder.errors.AssignmentError` naming the
file, the key and what to do.
"""

from __future__ import annotations

import datetime as dt
import difflib
import hashlib
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import nbformat

import autograder
from autograder.engine.celltests import CellTest, ManualCell
from autograder.engine.forbidden import Rules
from autograder.engine.nbgrader_source import course_source_dir, is_nbgrader_folder, nbgrader_parts
from autograder.engine.otter_format import otter_parts
from autograder.engine.variants import VariantSpec, parse_variants
from autograder.errors import AssignmentError

__all__ = [
    "Assignment",
    "load_assignment",
    "list_assignments",
    "default_search_root",
    "checks_digest",
    "SANDBOX_LIMITS",
]

#: Keys of ``[limits]`` passed on to ``autograder.sandbox.policy.Limits``.
SANDBOX_LIMITS = ("memory_bytes", "cpu_seconds", "processes", "open_files",
                  "file_size_bytes", "output_bytes")
_TIMEOUTS = ("notebook_timeout", "call_timeout")
_ALLOWED = {
    "assignment": ("name", "title", "notebook", "data", "format", "requirements", "deadline"),
    "rules": ("forbid", "reason", "internal_use"),
    "limits": _TIMEOUTS + SANDBOX_LIMITS,
    "variants": (),  # checked by autograder.engine.variants
    # read by ``validate --mutants`` (autograder.authoring.mutants_run), never by grading
    "mutants": ("min_kill_rate", "max"),
}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_DOTTED = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
_TOML = "assignment.toml"


@dataclass(frozen=True)
class Assignment:
    """A loaded assignment folder; all paths are absolute.

    Attributes
    ----------
    name, title : str
        The name (default: the folder name) and a human title.
    root : Path
        The assignment folder.
    notebook : Path
        The instructor notebook (with solutions).
    data_files : tuple of Path
        Public data files matched by the ``data`` globs, sorted.
    public_checks, hidden_checks : tuple of Path
        ``checks/public/test_*.py`` and ``checks/hidden/test_*.py``, sorted.
    rules : Rules
        Forbidden names.
    notebook_timeout, call_timeout : float
        Seconds for running the whole notebook, and for one call from a check.
    limits : tuple of (str, int or float)
        Overrides for ``autograder.sandbox.policy.Limits``, sorted by name; build the
        limits with ``Limits(**dict(assignment.limits))``.
    checks_digest : str
        SHA-256 over ``assignment.toml`` and every file under ``checks/``
        (path and contents, sorted by relative path): changes when grading
        could change.
    notebooks : tuple of Path
        Every instructor notebook of the assignment, ``notebook`` first; a student
        hands in one notebook of the same file name for each. Default:
        ``(notebook,)``.
    cell_tests : tuple of CellTest
        Tests written as notebook cells (nbgrader or otter courses).
    manual_cells : tuple of ManualCell
        Cells a person grades (nbgrader's manually graded answers and tasks).
    requirements : tuple of str
        Extra packages the student's code needs (pip requirement strings).
    variants : VariantSpec or None
        The per-student parameters (``[variants]``, see :mod:`autograder.engine.variants`).
    deadline : datetime or None
        ``[assignment] deadline`` (a TOML date-time with its zone): checks marked
        ``visibility("after_deadline")`` show their details once it has passed.
    """

    name: str
    title: str
    root: Path
    notebook: Path
    data_files: tuple[Path, ...]
    public_checks: tuple[Path, ...]
    hidden_checks: tuple[Path, ...]
    rules: Rules = field(default_factory=Rules)
    notebook_timeout: float = 60.0
    call_timeout: float = 10.0
    limits: tuple[tuple[str, int | float], ...] = ()
    checks_digest: str = ""
    notebooks: tuple[Path, ...] = ()
    cell_tests: tuple[CellTest, ...] = ()
    requirements: tuple[str, ...] = ()
    manual_cells: tuple[ManualCell, ...] = ()
    variants: VariantSpec | None = None
    deadline: dt.datetime | None = None

    def __post_init__(self) -> None:
        if not self.notebooks:
            object.__setattr__(self, "notebooks", (self.notebook,))


def default_search_root() -> Path:
    """The folder holding ``assignments/``: the repository, else the current directory.

    The repository is the parent of the installed ``autograder`` package (an
    editable install); it is used when it has an ``assignments/`` folder.
    """
    repository = Path(autograder.__file__).resolve().parent.parent
    if (repository / "assignments").is_dir():
        return repository
    return Path.cwd()


def list_assignments(search_root: Path | None = None) -> list[str]:
    """Names of the assignment folders (those with an ``assignment.toml``), sorted.

    Parameters
    ----------
    search_root : Path, optional
        A folder holding ``assignments/``, or the ``assignments/`` folder
        itself. Default: :func:`default_search_root`.
    """
    folder = _assignments_dir(search_root)
    if not folder.is_dir():
        return []
    return sorted(p.name for p in folder.iterdir() if _is_assignment(p))


def load_assignment(spec: str | Path, *, search_root: Path | None = None) -> Assignment:
    """Load an assignment by name or by path.

    Parameters
    ----------
    spec : str or Path
        A folder name under ``assignments/`` (``"hull"``), or a path to an
        assignment folder or to its ``assignment.toml``. A :class:`Path`, or a
        string holding a path separator, is always taken as a path.
    search_root : Path, optional
        Where to look names up: a folder holding ``assignments/``, or the
        ``assignments/`` folder itself. Default: :func:`default_search_root`.

    Returns
    -------
    Assignment

    Raises
    ------
    AssignmentError
        Unknown name, missing or malformed ``assignment.toml``, missing
        notebook, a data glob matching nothing, no checks.
    """
    root = _find_root(spec, search_root)
    toml_path = root / _TOML
    if not toml_path.is_file():  # an nbgrader source folder as it is
        return _build(root, toml_path, {"assignment": {"format": "nbgrader"}})
    config = _read_toml(toml_path)
    return _build(root, toml_path, config)


# -- finding the folder --------------------------------------------------------

def _assignments_dir(search_root: Path | None) -> Path:
    base = Path(search_root) if search_root is not None else default_search_root()
    if (base / "assignments").is_dir():
        return base / "assignments"
    return course_source_dir(base) or base


def _is_assignment(folder: Path) -> bool:
    """An assignment folder: one with ``assignment.toml``, or an nbgrader source folder."""
    return (folder / _TOML).is_file() or (folder.is_dir() and is_nbgrader_folder(folder))


def _find_root(spec: str | Path, search_root: Path | None) -> Path:
    if isinstance(spec, str) and not spec.strip():
        raise AssignmentError("The assignment name is empty; give a name or a folder.")
    if isinstance(spec, str) and not _looks_like_path(spec):
        candidate = _assignments_dir(search_root) / spec
        if candidate.is_dir():
            return _checked_root(candidate)
        if Path(spec).is_dir():
            return _checked_root(Path(spec))
        raise _unknown(spec, search_root)
    path = Path(spec)
    if path.name == _TOML and path.is_file():
        path = path.parent
    if not path.is_dir():
        raise AssignmentError(f"Assignment folder {str(path)!r} does not exist; "
                              "give a name under assignments/ or an existing folder.")
    return _checked_root(path)


def _looks_like_path(spec: str) -> bool:
    return "/" in spec or "\\" in spec or spec in (".", "..") or spec.endswith(_TOML)


def _checked_root(path: Path) -> Path:
    root = path.resolve()
    if course_source_dir(root) is not None:
        raise AssignmentError(
            f"{root} is an nbgrader course root; name one of its assignments: "
            f"'--course {root} ps1', or the folder {root / 'source' / 'ps1'} (for ps1).")
    if not _is_assignment(root):
        raise AssignmentError(
            f"{root} has no {_TOML} and no nbgrader notebook; an assignment folder needs "
            "one or the other (see 'An assignment folder' in docs/design.md, and "
            "docs/coming-from-nbgrader-or-otter.md).")
    return root


def _unknown(spec: str, search_root: Path | None) -> AssignmentError:
    folder = _assignments_dir(search_root)
    names = list_assignments(search_root)
    if not names:
        return AssignmentError(f"Unknown assignment {spec!r}: there are no assignments in "
                               f"{folder}. Give the path to an assignment folder instead.")
    close = difflib.get_close_matches(spec, names, n=1)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    return AssignmentError(f"Unknown assignment {spec!r}.{hint} Available in {folder}: "
                           f"{', '.join(names)}.")


# -- reading the TOML ----------------------------------------------------------

def _read_toml(path: Path) -> dict[str, Any]:
    try:
        with path.open("rb") as handle:
            config = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise AssignmentError(f"{path}: TOML syntax error: {exc}. Fix the file.") from None
    except UnicodeDecodeError:
        raise AssignmentError(f"{path}: not UTF-8 text; save it as UTF-8.") from None
    except OSError as exc:
        raise AssignmentError(f"{path}: cannot be read ({exc.strerror or exc}).") from None
    _check_keys(path, config)
    return config


def _check_keys(path: Path, config: dict[str, Any]) -> None:
    unknown = sorted(set(config) - set(_ALLOWED) - {"manual"})  # [[manual]]: see _manual_cells
    if unknown:
        raise AssignmentError(f"{path}: unknown table(s) {_listed(unknown)}; "
                              f"allowed tables: {_listed([*_ALLOWED, 'manual'])}.")
    for table, allowed in _ALLOWED.items():
        if table == "variants":
            continue
        section = config.get(table, {})
        if not isinstance(section, dict):
            raise AssignmentError(f"{path}: '{table}' must be a table ([{table}]).")
        unknown = sorted(set(section) - set(allowed))
        if unknown:
            raise AssignmentError(f"{path}: unknown key(s) {_listed(unknown)} in [{table}]; "
                                  f"allowed keys: {_listed(allowed)}.")


def _listed(names: Any) -> str:
    return ", ".join(repr(n) for n in names)


def _get(path: Path, config: dict[str, Any], table: str, key: str,
         kind: type | tuple[type, ...], default: Any) -> Any:
    """``config[table][key]`` checked against ``kind``, else ``default``."""
    section = config.get(table, {})
    if key not in section:
        return default
    value = section[key]
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        want = " or ".join(k.__name__ for k in kinds)
        raise AssignmentError(f"{path}: [{table}] {key} must be {_article(want)}; "
                              f"got {type(value).__name__} {value!r}.")
    return value


def _article(word: str) -> str:
    names = {"str": "a string", "list": "a list", "int": "an integer",
             "int or float": "a number", "float": "a number"}
    return names.get(word, word)


def _string_list(path: Path, config: dict[str, Any], table: str, key: str) -> tuple[str, ...]:
    values = _get(path, config, table, key, list, [])
    for value in values:
        if not isinstance(value, str) or not value.strip():
            raise AssignmentError(f"{path}: [{table}] {key} must be a list of non-empty "
                                  f"strings; got {value!r} in it.")
    return tuple(values)


# -- building the Assignment ---------------------------------------------------

def _build(root: Path, toml_path: Path, config: dict[str, Any]) -> Assignment:
    name = _name(root, toml_path, config)
    title = _get(toml_path, config, "assignment", "title", str, name)
    form = _get(toml_path, config, "assignment", "format", str, "numgrade")
    if form not in ("numgrade", "nbgrader"):
        raise AssignmentError(f"{toml_path}: [assignment] format must be 'numgrade' or "
                              f"'nbgrader'; got {form!r}.")
    named = _get(toml_path, config, "assignment", "notebook", str, None)
    parts = nbgrader_parts(root, first=named) if form == "nbgrader" else None
    default = parts.notebooks[0].name if parts is not None else f"{name}.ipynb"
    notebook = _notebook(root, toml_path, named or default)
    data = _data_files(root, toml_path, _string_list(toml_path, config, "assignment", "data"))
    public, hidden = _checks(root, "public"), _checks(root, "hidden")
    otter = otter_parts(root, notebook) if parts is None else None  # otter's master notebook
    requirements = (_string_list(toml_path, config, "assignment", "requirements")
                    + (otter[1] if otter is not None else ()))
    cells = bool(otter and otter[0]) or bool(parts and (parts.cell_tests or parts.manual_cells))
    if not public and not hidden and not cells:
        raise AssignmentError(
            f"{root} has no checks: add test_*.py files under checks/public/ (released to "
            "students) or checks/hidden/ (kept back)"
            + (", or autograder test cells with points to the notebooks." if parts else "."))
    timeouts, limits = _limits(toml_path, config)
    extra: dict[str, Any] = {"requirements": requirements,
                             "variants": parse_variants(root, toml_path, config.get("variants"),
                                                         notebook),
                             "deadline": _deadline(toml_path, config)}
    if otter is not None:
        extra["cell_tests"] = otter[0]
    if parts is None and "manual" in config:
        extra["manual_cells"] = _manual_cells(toml_path, config["manual"], notebook)
    if parts is not None:
        extra.update({"notebooks": parts.notebooks, "cell_tests": parts.cell_tests,
                      "manual_cells": parts.manual_cells,
                      "data_files": tuple(sorted(set(data) | set(parts.extra_files)))})
    return Assignment(**{
        "name": name, "title": title, "root": root, "notebook": notebook, "data_files": data,
        "public_checks": public, "hidden_checks": hidden, "rules": _rules(toml_path, config),
        "notebook_timeout": timeouts["notebook_timeout"],
        "call_timeout": timeouts["call_timeout"], "limits": limits,
        "checks_digest": checks_digest(root), **extra})


def _manual_cells(toml_path: Path, entries: Any, notebook: Path) -> tuple[ManualCell, ...]:
    """``[[manual]] cell = "NAME"  points = N``: the notebook's cell tagged ``manual:NAME``."""
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise AssignmentError(f"{toml_path}: write each manually graded cell as a [[manual]] "
                              "table with cell = \"NAME\" and points = N.")
    tags = _manual_tags(notebook)
    found = []
    for number, entry in enumerate(entries, start=1):
        cell, points = entry.get("cell"), entry.get("points")
        if set(entry) - {"cell", "points"}:
            raise AssignmentError(f"{toml_path}: [[manual]] number {number} has unknown key(s) "
                                  f"{_listed(sorted(set(entry) - {'cell', 'points'}))}; "
                                  "allowed: 'cell', 'points'.")
        if not isinstance(cell, str) or not cell or isinstance(points, bool) \
                or not isinstance(points, (int, float)) or points <= 0:
            raise AssignmentError(f"{toml_path}: [[manual]] number {number} needs cell = \"NAME\" "
                                  f"and points = a positive number; got {entry!r}.")
        if cell not in tags:
            raise AssignmentError(f"{toml_path}: [[manual]] cell {cell!r} has no cell in "
                                  f"{notebook.name}; tag the answer cell manual:{cell}.")
        found.append(ManualCell(name=cell, notebook=notebook.name, points=float(points)))
    return tuple(found)


def _manual_tags(notebook: Path) -> set[str]:
    try:
        book = nbformat.read(str(notebook), as_version=4)
    except Exception:  # nbformat raises several kinds for a damaged file
        raise AssignmentError(f"The instructor notebook {notebook} cannot be read; open it in "
                              "Jupyter and save it again.") from None
    return {t[len("manual:"):] for c in book.cells for t in c.get("metadata", {}).get("tags", [])
            if isinstance(t, str) and t.startswith("manual:")}


def _deadline(toml_path: Path, config: dict[str, Any]) -> dt.datetime | None:
    value = _get(toml_path, config, "assignment", "deadline", dt.datetime, None)
    if value is not None and value.tzinfo is None:
        raise AssignmentError(f"{toml_path}: [assignment] deadline must carry its time zone "
                              f"(e.g. 2026-12-01T17:00:00Z); got {value}.")
    return value


def _name(root: Path, toml_path: Path, config: dict[str, Any]) -> str:
    name = _get(toml_path, config, "assignment", "name", str, root.name)
    if not _NAME.match(name):
        raise AssignmentError(f"{toml_path}: [assignment] name {name!r} must use only letters, "
                              "digits, '_', '-' and '.'.")
    return name


def _inside(root: Path, path: Path) -> bool:
    try:
        path.resolve().relative_to(root)
    except ValueError:
        return False
    return True


def _notebook(root: Path, toml_path: Path, relative: str) -> Path:
    path = root / relative
    if not _inside(root, path):
        raise AssignmentError(f"{toml_path}: [assignment] notebook {relative!r} must be inside "
                              f"{root}.")
    if not path.is_file():
        raise AssignmentError(f"{toml_path}: the notebook {relative!r} was not found in {root}; "
                              "add it, or set [assignment] notebook to its name.")
    return path.resolve()


def _data_files(root: Path, toml_path: Path, globs: tuple[str, ...]) -> tuple[Path, ...]:
    found: set[Path] = set()
    for pattern in globs:
        if Path(pattern).is_absolute() or ".." in Path(pattern).parts:
            raise AssignmentError(f"{toml_path}: data glob {pattern!r} must be relative to the "
                                  "assignment folder, without '..'.")
        try:
            matches = {p for p in root.glob(pattern) if p.is_file()}
        except ValueError as exc:
            raise AssignmentError(f"{toml_path}: data glob {pattern!r} is not a valid "
                                  f"pattern ({exc}).") from None
        if not matches:
            raise AssignmentError(f"{toml_path}: data glob {pattern!r} matches no file in "
                                  f"{root}; fix the pattern or add the files.")
        for path in matches:
            _check_data_file(root, toml_path, pattern, path)
        found |= matches
    return tuple(sorted(found))


def _check_data_file(root: Path, toml_path: Path, pattern: str, path: Path) -> None:
    if not _inside(root, path):
        raise AssignmentError(f"{toml_path}: data glob {pattern!r} matches {path}, which "
                              "points outside the assignment folder.")
    if path.relative_to(root).parts[0] == "checks":
        raise AssignmentError(f"{toml_path}: data glob {pattern!r} matches {path}, under "
                              "checks/; data files are released, so keep them out of checks/.")


def _checks(root: Path, which: str) -> tuple[Path, ...]:
    folder = root / "checks" / which
    return tuple(sorted(p for p in folder.glob("test_*.py") if p.is_file()))


def _rules(toml_path: Path, config: dict[str, Any]) -> Rules:
    forbid = _string_list(toml_path, config, "rules", "forbid")
    for name in forbid:
        if not _DOTTED.match(name):
            raise AssignmentError(f"{toml_path}: [rules] forbid entry {name!r} must be a dotted "
                                  "name such as 'scipy.spatial' or 'numpy.linalg.solve'.")
    default = (f"This assignment does not allow {', '.join(forbid)}." if forbid else "")
    reason = _get(toml_path, config, "rules", "reason", str, default)
    internal = _string_list(toml_path, config, "rules", "internal_use")
    stray = [name for name in internal if name not in forbid]
    if stray:
        raise AssignmentError(f"{toml_path}: [rules] internal_use lists {', '.join(stray)}, "
                              "which [rules] forbid does not; list only forbidden names there.")
    return Rules(forbid=forbid, reason=reason, internal_use=internal)


def _limits(toml_path: Path, config: dict[str, Any]
            ) -> tuple[dict[str, float], tuple[tuple[str, int | float], ...]]:
    """The two timeouts, and the sandbox overrides sorted by name."""
    timeouts = {"notebook_timeout": 60.0, "call_timeout": 10.0}
    overrides: list[tuple[str, int | float]] = []
    for key in _TIMEOUTS + SANDBOX_LIMITS:
        kind: tuple[type, ...] = (int, float) if key in _TIMEOUTS + ("cpu_seconds",) else (int,)
        value = _get(toml_path, config, "limits", key, kind, None)
        if value is None:
            continue
        if value <= 0:
            raise AssignmentError(f"{toml_path}: [limits] {key} must be positive; got {value!r}.")
        if key in _TIMEOUTS:
            timeouts[key] = float(value)
        else:
            overrides.append((key, value))
    return timeouts, tuple(sorted(overrides))


def checks_digest(root: Path) -> str:
    """SHA-256 over ``assignment.toml`` and the files under ``checks/``.

    Each file contributes its path relative to ``root`` and the digest of its
    bytes, in order of path; caches (``__pycache__``, ``*.pyc``) are skipped.
    """
    files = [root / _TOML] * (root / _TOML).is_file() + [
        p for p in (root / "checks").rglob("*")
        if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"
    ]
    digest = hashlib.sha256()
    for path in sorted(files, key=lambda p: p.relative_to(root).as_posix()):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(path.read_bytes()).digest())
    return digest.hexdigest()
