"""Read and validate a submitted notebook, and extract its code cells.

A submission passes through small steps, each of which either hands clean data
to the next or raises :class:`~autograder.errors.NotebookError` with a ``kind``
and a message written for the student (what is wrong and what to do):

``unreadable``
    the path is missing, is not a regular file, or cannot be opened.
``too-large``
    the file is over ``max_bytes`` (checked before reading it), or its code is
    over ``max_code_bytes``.
``binary`` / ``encoding``
    the bytes are not UTF-8 text: a binary file (image, archive, PDF), or a
    text file saved in another encoding (UTF-16, Latin-1).
``not-json``
    the text is not JSON; the message gives the line and column.
``not-notebook``
    valid JSON, but not an object holding notebook cells.
``old-format``
    an nbformat version older than 3 (version 3 is upgraded to 4 silently).
``invalid``
    the cells cannot be read (a cell is not an object, or a code cell's source
    is not text). Smaller schema problems, such as bad metadata or missing
    cell ids, do not stop grading: they are reported in
    :attr:`Notebook.warnings`.
``language``
    the notebook's kernel is not Python.

A notebook with no code (no code cells, or only blank ones) is *not* an error:
:func:`read_notebook` returns a :class:`Notebook` with no cells, and the grader
scores it zero with :data:`EMPTY_NOTEBOOK_MESSAGE`.

Outputs are never kept: a notebook that is large only because of its outputs is
graded as long as the file is under ``max_bytes``.
"""

from __future__ import annotations

import copy
import hashlib
import json
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import nbformat
from nbformat.validator import normalize

from autograder.boundary.limits import MAX_CELLS
from autograder.errors import NotebookError

__all__ = [
    "Cell",
    "Notebook",
    "parse_notebook",
    "read_notebook",
    "code_sources",
    "LockedCells",
    "locked_cells",
    "locked_sources",
    "restore_locked",
    "MAX_NOTEBOOK_BYTES",
    "MAX_CODE_BYTES",
    "EMPTY_NOTEBOOK_MESSAGE",
    "ERROR_KINDS",
]

#: Default limit on the size of a submitted file.
MAX_NOTEBOOK_BYTES = 20 * 2**20
#: Default limit on the total size of the code cells' sources.
MAX_CODE_BYTES = 2 * 2**20
#: What the grader tells a student whose notebook holds no code.
EMPTY_NOTEBOOK_MESSAGE = (
    "Your notebook contains no code, so there was nothing to grade. "
    "Check that you submitted the notebook you worked in, and that you saved it first."
)
#: Every ``NotebookError.kind`` this module raises.
ERROR_KINDS = (
    "unreadable", "too-large", "binary", "encoding", "not-json",
    "not-notebook", "old-format", "invalid", "language", "not-regular",
)

_RESAVE = "Open it in Jupyter, save it (File > Save), and submit the .ipynb file again."
_CLEAR_OUTPUTS = "Clear all outputs (Kernel > Restart & Clear Output) and submit again."
_LANGUAGE_NAMES = {
    "julia": "Julia", "r": "R", "ir": "R", "matlab": "MATLAB", "octave": "Octave",
    "c++": "C++", "cpp": "C++", "c": "C", "javascript": "JavaScript",
    "typescript": "TypeScript", "sas": "SAS", "scala": "Scala", "java": "Java",
    "bash": "Bash", "sql": "SQL", "rust": "Rust", "go": "Go", "sage": "SageMath",
}
_MAGIC_NUMBERS = (
    (b"PK\x03\x04", "a ZIP archive"),
    (b"%PDF", "a PDF document"),
    (b"\x89PNG", "a PNG image"),
    (b"\xff\xd8\xff", "a JPEG image"),
    (b"\x1f\x8b", "a gzip archive"),
    (b"Rar!", "a RAR archive"),
    (b"7z\xbc\xaf", "a 7-Zip archive"),
    (b"\xd0\xcf\x11\xe0", "a Microsoft Office document"),
)


@dataclass(frozen=True)
class Cell:
    """One code cell of a submitted notebook.

    Attributes
    ----------
    index : int
        Position of the cell among *all* cells of the notebook (markdown
        included), counting from 0.
    source : str
        The cell's source, lines joined.
    cell_id : str or None
        The cell's ``id`` field (nbformat 4.5), as found in the file.
    grade_id : str or None
        ``metadata.nbgrader.grade_id`` when the cell came from an nbgrader
        template.
    kind : str
        Always ``"code"``: only code cells are kept.
    """

    index: int
    source: str
    cell_id: str | None = None
    grade_id: str | None = None
    kind: str = "code"


@dataclass(frozen=True)
class Notebook:
    """A submitted notebook reduced to what the grader needs.

    Attributes
    ----------
    path : Path
        The file that was read.
    cells : tuple of Cell
        The non-blank code cells, in order. Empty for a notebook with no code.
    nbformat : int
        The major format version of the file as submitted (3 or 4).
    language : str
        The kernel language, lower case (``"python"``).
    sha256 : str
        Hex digest of the file's raw bytes.
    warnings : tuple of str
        Problems that did not stop grading, written for the student.
    """

    path: Path
    cells: tuple[Cell, ...]
    nbformat: int
    language: str
    sha256: str
    warnings: tuple[str, ...] = ()

    @property
    def end(self) -> int:
        """An index past every code cell (where tests of deleted cells are put)."""
        return max((c.index for c in self.cells), default=-1) + 1

    @property
    def is_empty(self) -> bool:
        """True when the notebook holds no code to run."""
        return not self.cells


def read_notebook(
    path: str | Path,
    *,
    max_bytes: int = MAX_NOTEBOOK_BYTES,
    max_code_bytes: int = MAX_CODE_BYTES,
) -> Notebook:
    """Read ``path`` as a notebook and keep its code cells.

    Parameters
    ----------
    path : str or Path
        The submitted file.
    max_bytes : int, optional
        Largest accepted file size; checked before the file is read.
    max_code_bytes : int, optional
        Largest accepted total size (UTF-8) of the code cells' sources.

    Returns
    -------
    Notebook
        The code cells and facts about the file. Outputs are dropped.

    Raises
    ------
    NotebookError
        For any file that cannot be graded; ``kind`` is one of
        :data:`ERROR_KINDS` and the message says what to do. No other
        exception escapes for bad input.
    """
    path = Path(path)
    return parse_notebook(_read_bytes(path, max_bytes), path=path, max_code_bytes=max_code_bytes)


def parse_notebook(raw: bytes, *, path: str | Path = "upload.ipynb",
                   max_code_bytes: int = MAX_CODE_BYTES) -> Notebook:
    """Read the bytes of a notebook file, as :func:`read_notebook` reads a file.

    For a notebook that is not on disk (an upload being checked); ``path`` is only
    recorded in the result. The caller bounds the size of ``raw``.
    """
    text = _decode(raw)
    document = _parse_json(text)
    major = _check_version(document)
    cells_json, nb = _to_v4(document, major)
    cells = _code_cells(cells_json)
    _check_code_size(cells, max_code_bytes)
    language = _language(nb.get("metadata"))
    # A notebook of more code cells than the worker runs is refused before it runs
    # (student_process.check_cell_count), so a warning about its format would never be
    # read; validating its hundreds of thousands of cells cost the grader 10+ s of CPU.
    notes = _validation_warnings(nb) if len(cells) <= MAX_CELLS else ()
    return Notebook(path=Path(path), cells=cells, nbformat=major, language=language,
                    sha256=hashlib.sha256(raw).hexdigest(), warnings=notes)


def code_sources(nb: Notebook) -> list[str]:
    """The sources of ``nb``'s code cells, in order."""
    return [cell.source for cell in nb.cells]


# -- bytes and text ------------------------------------------------------------

def _mb(n: int) -> str:
    return f"{n / 2**20:.1f} MB"


def _too_large(size: int, max_bytes: int) -> NotebookError:
    return NotebookError(
        f"The file is {_mb(size)}, larger than the {_mb(max_bytes)} limit; this usually "
        f"means it holds large outputs (pictures, long printouts). {_CLEAR_OUTPUTS}",
        kind="too-large")


def _read_bytes(path: Path, max_bytes: int) -> bytes:
    """At most ``max_bytes`` of ``path``; the size is checked before reading."""
    try:
        if not path.is_file():
            what = "does not exist" if not path.exists() else "is not a file"
            raise NotebookError(f"{path.name!r} {what}. Submit your .ipynb notebook file.",
                                kind="unreadable")
        size = path.stat().st_size
        if size > max_bytes:
            raise _too_large(size, max_bytes)
        with path.open("rb") as handle:
            raw = handle.read(max_bytes + 1)
    except OSError as exc:
        raise NotebookError(f"The file could not be opened ({exc.strerror or exc}). "
                            "Submit it again.", kind="unreadable") from None
    if len(raw) > max_bytes:  # grew since stat, or a special file
        raise _too_large(len(raw), max_bytes)
    return raw


def _decode(raw: bytes) -> str:
    """``raw`` as UTF-8 text (a UTF-8 byte-order mark is allowed)."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise NotebookError(
            "The file is saved as UTF-16 text, but notebooks must be UTF-8. " + _RESAVE,
            kind="encoding")
    for magic, what in _MAGIC_NUMBERS:
        if raw.startswith(magic):
            raise NotebookError(f"This file is {what}, not a Jupyter notebook. "
                                "Submit the .ipynb file itself.", kind="binary")
    if b"\x00" in raw:
        raise NotebookError("This is a binary file, not a Jupyter notebook (which is text). "
                            "Submit the .ipynb file itself.", kind="binary")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise NotebookError(
            f"The file is not UTF-8 text (bad byte at line {line}); it may have been "
            f"saved by another editor in a different encoding. {_RESAVE}",
            kind="encoding") from None


def _parse_json(text: str) -> Any:
    """The JSON document in ``text``; errors give the line and column."""
    if not text.strip():
        raise NotebookError("The file is empty. " + _RESAVE, kind="not-json")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise NotebookError(
            f"The file is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg}); "
            f"it may be damaged or have been edited outside Jupyter. {_RESAVE}",
            kind="not-json") from None
    except (ValueError, RecursionError) as exc:  # huge integers, absurd nesting
        raise NotebookError(f"The file could not be read as JSON ({type(exc).__name__}). "
                            + _RESAVE, kind="not-json") from None


# -- structure -----------------------------------------------------------------

def _not_notebook(detail: str) -> NotebookError:
    return NotebookError(
        f"This file is JSON but not a Jupyter notebook ({detail}). "
        "Submit the .ipynb notebook you worked in.", kind="not-notebook")


def _check_version(document: Any) -> int:
    """The major nbformat version of ``document``, which must be 3 or 4."""
    if not isinstance(document, dict):
        raise _not_notebook(f"it holds a {_json_type(document)}, not an object with cells")
    if "cells" not in document and "worksheets" not in document:
        raise _not_notebook("it has no cells")
    major = document.get("nbformat")
    if not isinstance(major, int) or isinstance(major, bool):
        raise _not_notebook("it has no valid 'nbformat' version number")
    if major < 3:
        raise NotebookError(
            f"This notebook uses format version {major}, which is too old to grade. "
            "Open it in a current Jupyter, save it, and submit again.", kind="old-format")
    if major > 4:
        raise NotebookError(
            f"This notebook uses format version {major}, which this grader does not know. "
            "Save it from a standard Jupyter installation and submit again.", kind="invalid")
    return major


def _json_type(value: Any) -> str:
    names = {list: "list", str: "string", int: "number", float: "number",
             bool: "boolean", type(None): "null"}
    return names.get(type(value), type(value).__name__)


def _to_v4(document: dict[str, Any], major: int) -> tuple[list[Any], Any]:
    """``(cells, notebook)`` in format 4; version 3 is upgraded."""
    if major == 4:
        cells = document.get("cells")
        if not isinstance(cells, list):
            raise _invalid(f"'cells' is a {_json_type(cells)}, not a list")
        return cells, document
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            nb = nbformat.versions[3].to_notebook_json(
                copy.deepcopy(document), minor=document.get("nbformat_minor", 0))
            nb = nbformat.convert(nb, 4)
    except Exception as exc:  # nbformat's upgrade raises many types on bad input
        raise _invalid(f"it could not be upgraded from format 3: {_one_line(exc)}") from None
    return list(nb.get("cells", [])), nb


def _invalid(detail: str) -> NotebookError:
    return NotebookError(f"The notebook's contents are damaged ({detail}). " + _RESAVE,
                         kind="invalid")


def _code_cells(cells_json: list[Any]) -> tuple[Cell, ...]:
    """The non-blank code cells; raises ``invalid`` when a cell cannot be read."""
    cells: list[Cell] = []
    for index, cell in enumerate(cells_json):
        if not isinstance(cell, dict) or not isinstance(cell.get("cell_type"), str):
            raise _invalid(f"cell {index + 1} is not a notebook cell")
        if cell["cell_type"] != "code":
            continue
        source = _source_text(cell.get("source", ""), index)
        if source.strip():
            cells.append(Cell(index=index, source=source, cell_id=_str_or_none(cell.get("id")),
                              grade_id=_grade_id(cell.get("metadata"))))
    return tuple(cells)


def _source_text(source: Any, index: int) -> str:
    if isinstance(source, str):
        return source
    if isinstance(source, list) and all(isinstance(line, str) for line in source):
        return "".join(source)
    raise _invalid(f"the source of cell {index + 1} is not text")


def _str_or_none(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def _grade_id(metadata: Any) -> str | None:
    if isinstance(metadata, dict) and isinstance(metadata.get("nbgrader"), dict):
        return _str_or_none(metadata["nbgrader"].get("grade_id"))
    return None


def _check_code_size(cells: tuple[Cell, ...], max_code_bytes: int) -> None:
    size = sum(len(cell.source.encode("utf-8", "surrogatepass")) for cell in cells)
    if size > max_code_bytes:
        raise NotebookError(
            f"The code in this notebook is {_mb(size)}, more than the {_mb(max_code_bytes)} "
            "limit. Do not paste data into code cells: load it from a file instead, "
            "then submit again.", kind="too-large")


# -- language ------------------------------------------------------------------

def _language(metadata: Any) -> str:
    """The kernel language (lower case); raises ``language`` unless it is Python.

    Looks at ``kernelspec.language``, then ``language_info.name``, then
    ``kernelspec.name``; a notebook that records none of them is taken to be
    Python.
    """
    metadata = metadata if isinstance(metadata, dict) else {}
    kernelspec = metadata.get("kernelspec") if isinstance(metadata.get("kernelspec"), dict) else {}
    info = metadata.get("language_info") if isinstance(metadata.get("language_info"), dict) else {}
    for candidate in (kernelspec.get("language"), info.get("name"), kernelspec.get("name")):
        if isinstance(candidate, str) and candidate.strip():
            language = candidate.strip().lower()
            break
    else:
        return "python"
    if language.startswith(("python", "ipython")):
        return "python"
    base = language.split("-")[0].rstrip("0123456789.")
    name = _LANGUAGE_NAMES.get(base, _LANGUAGE_NAMES.get(language, candidate.strip()))
    raise NotebookError(
        f"This notebook runs {name}, but the assignment needs a Python 3 notebook. "
        "Start from the assignment's notebook, choose the Python 3 kernel "
        "(Kernel > Change Kernel), and submit again.", kind="language")


# -- schema --------------------------------------------------------------------

def _validation_warnings(nb: Any) -> tuple[str, ...]:
    """A one-line warning when ``nb`` breaks the nbformat schema, else ``()``.

    Outputs are removed before validating: they are never used, and damaged
    outputs must not stop grading.
    """
    try:
        stripped = _without_outputs(nb)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, normalized = normalize(stripped)
            nbformat.validate(normalized)
    except nbformat.ValidationError as exc:
        return (_schema_warning(_schema_summary(exc)),)
    except Exception as exc:  # the validator itself failed on odd input
        return (_schema_warning(_one_line(exc)),)
    return ()


def _without_outputs(nb: Any) -> dict[str, Any]:
    document = {key: value for key, value in dict(nb).items() if key != "cells"}
    cells = []
    for cell in nb.get("cells", []):
        cell = dict(cell)
        if cell.get("cell_type") == "code":
            cell["outputs"], cell["execution_count"] = [], None
        cells.append(cell)
    document["cells"] = cells
    # No deep copy here: nbformat's normalize() deep-copies what it is given before it
    # changes anything (its documented return: "deep-copy of the original object"), and a
    # second copy doubled the cost of a large notebook.
    return document


def _schema_summary(exc: nbformat.ValidationError) -> str:
    where = "".join(f"[{p}]" if isinstance(p, int) else f".{p}"
                    for p in getattr(exc, "absolute_path", ()))
    message = getattr(exc, "message", None) or str(exc)
    return f"{where.lstrip('.') or 'notebook'}: {_one_line(message)}"


def _schema_warning(summary: str) -> str:
    return (f"The notebook file does not follow the Jupyter format exactly ({summary}); "
            "it was graded anyway. Saving it again in Jupyter usually fixes this.")


def _one_line(value: object, limit: int = 160) -> str:
    text = " ".join(str(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


# -- locked cells --------------------------------------------------------------

@dataclass(frozen=True)
class LockedCells:
    """The instructor notebook's locked code cells, and where they sit.

    Attributes
    ----------
    sources : dict of str to str
        ``grade_id -> source`` of the locked read-only cells that are neither
        solution nor test cells (helpers, imports, data loading): the release
        leaves their source unchanged, so the instructor's copy is the released
        one. Test cells are left out on purpose: their instructor version holds
        hidden tests (they are run by :mod:`autograder.engine.celltests`).
    tests : frozenset of str
        ``grade_id`` of the locked test cells (``grade`` and not ``solution``).
    order : tuple of str
        ``grade_id`` of every code cell of the instructor notebook, in order: the
        anchors that say where a locked cell belongs in a student's notebook.
    cell_ids : dict of str to str
        ``grade_id -> cell id`` (nbformat 4.5) of the locked cells, where known: a
        student's cell keeps its id when its metadata is removed.
    """

    sources: dict[str, str]
    tests: frozenset[str] = frozenset()
    order: tuple[str, ...] = ()
    cell_ids: dict[str, str] = field(default_factory=dict)

    def __bool__(self) -> bool:
        return bool(self.sources or self.tests)


def locked_sources(instructor: str | Path) -> dict[str, str]:
    """``grade_id -> source`` of the instructor notebook's locked read-only code cells."""
    return locked_cells(instructor).sources


def locked_cells(instructor: str | Path) -> LockedCells:
    """The :class:`LockedCells` of the instructor notebook ``instructor``."""
    nb = nbformat.read(str(instructor), as_version=4)
    sources: dict[str, str] = {}
    tests: set[str] = set()
    order: list[str] = []
    cell_ids: dict[str, str] = {}
    for cell in nb.cells:
        meta = cell.get("metadata", {}).get("nbgrader", {})
        grade_id = meta.get("grade_id")
        if cell.get("cell_type") != "code" or not isinstance(grade_id, str):
            continue
        order.append(grade_id)
        if not meta.get("locked") or meta.get("solution"):
            continue
        if isinstance(cell.get("id"), str):
            cell_ids[grade_id] = cell["id"]
        if meta.get("grade"):
            tests.add(grade_id)
        else:
            sources[grade_id] = _source_text(cell.get("source", ""), 0)
    return LockedCells(sources=sources, tests=frozenset(tests), order=tuple(order),
                       cell_ids=cell_ids)


def restore_locked(nb: Notebook, locked: LockedCells | dict[str, str]) -> Notebook:
    """``nb`` with every locked cell's source put back as released (nbgrader's OverwriteCells).

    A locked cell is matched by ``grade_id`` (or by its cell id, which survives a
    student removing the metadata) *and* by position: when several of the student's
    cells claim the same locked cell, the one whose place among the other graded
    cells matches the instructor notebook's is the one restored (a tie goes to the
    edited one, so edited code never runs under a locked cell's name); the others
    lose the ``grade_id`` and run as the student's own cells, and a note names them.
    Afterwards at most one cell carries each locked ``grade_id``. A changed or
    missing locked cell is named in the notebook's warnings, which the feedback
    page shows.
    """
    if isinstance(locked, dict):
        locked = LockedCells(sources=locked)
    if not locked:
        return nb
    chosen, duplicates = _match_locked(nb.cells, locked)
    cells, changed = [], []
    for position, cell in enumerate(nb.cells):
        grade_id = chosen.get(position)
        if grade_id is None:
            if cell.grade_id in locked.sources or cell.grade_id in locked.tests:
                cell = replace(cell, grade_id=None)  # a duplicate: the student's own cell
            cells.append(cell)
            continue
        original = locked.sources.get(grade_id)
        if original is not None and original != cell.source:
            changed.append(grade_id)
        cells.append(replace(cell, source=original if original is not None else cell.source,
                             grade_id=grade_id))
    present = set(chosen.values())
    missing = sorted(gid for gid in locked.sources if gid not in present and locked.sources[gid].strip())
    return replace(nb, cells=tuple(cells),
                   warnings=nb.warnings + _locked_warnings(changed, missing, duplicates))


def _locked_warnings(changed: list[str], missing: list[str], duplicates: list[str]
                     ) -> tuple[str, ...]:
    warnings = []
    if changed:
        warnings.append(
            "You changed read-only (locked) cell(s) " + ", ".join(f"`{g}`" for g in changed)
            + "; they were graded as released, without your changes.")
    if missing:
        warnings.append(
            "Read-only (locked) cell(s) " + ", ".join(f"`{g}`" for g in missing)
            + " are missing from your notebook; functions they define may be missing too. "
            "Start again from the released notebook if you deleted them.")
    if duplicates:
        warnings.append(
            "Your notebook holds more than one copy of read-only (locked) cell(s) "
            + ", ".join(f"`{g}`" for g in sorted(set(duplicates)))
            + "; the copy where the cell was released was graded as released, the other "
            "copies ran as your own code. A person may look at this.")
    return tuple(warnings)


def _match_locked(cells: tuple[Cell, ...], locked: LockedCells
                  ) -> tuple[dict[int, str], list[str]]:
    """``position -> grade_id`` of the student's cell restored for each locked cell,
    and the ``grade_id`` of locked cells claimed by more than one cell."""
    by_cell_id = {cid: gid for gid, cid in locked.cell_ids.items()}
    claims: dict[str, list[int]] = {}
    for position, cell in enumerate(cells):
        for grade_id in {cell.grade_id, by_cell_id.get(cell.cell_id or "")}:
            if grade_id in locked.sources or grade_id in locked.tests:
                claims.setdefault(grade_id, []).append(position)  # type: ignore[arg-type]
    seen: dict[str, list[int]] = {}
    for position, cell in enumerate(cells):
        if cell.grade_id is not None:
            seen.setdefault(cell.grade_id, []).append(position)
    chosen: dict[int, str] = {}
    duplicates = []
    for grade_id, positions in claims.items():
        if len(positions) > 1:
            duplicates.append(grade_id)
        best = max(positions, key=lambda p: (_fit(p, grade_id, locked.order, seen),
                                              cells[p].source != locked.sources.get(grade_id),
                                              -p))
        chosen[best] = grade_id
    return chosen, duplicates


def _fit(position: int, grade_id: str, order: tuple[str, ...], seen: dict[str, list[int]]) -> int:
    """How many graded cells lie on the side of ``position`` the instructor notebook puts them."""
    if grade_id not in order:
        return 0
    k = order.index(grade_id)
    before = sum(1 for g in order[:k] if any(p < position for p in seen.get(g, ())))
    after = sum(1 for g in order[k + 1:] if any(p > position for p in seen.get(g, ())))
    return before + after
