"""Per-student variants: the parameters an assignment draws for each student from a seed.

Declared in ``assignment.toml`` (all keys optional but ``params`` or a hook)::

    [variants]
    roster = "roster.csv"        # who has a variant (a CSV with a column student, id,
                                 # login, github_username or identifier); relative to the folder
    cell = "variant"             # tag of the instructor notebook's parameters cell
    secret_env = "NUMGRADE_VARIANT_SECRET"   # environment variable holding the course secret

    [variants.params.n]
    kind = "int"                 # int: low..high inclusive
    low = 5
    high = 9
    [variants.params.shape]
    kind = "choice"              # one of values (numbers, strings, data file names)
    values = ["circle", "square"]
    [variants.params.pins]
    kind = "points"              # n points in [low, high)^2, rounded to digits
    n = 8
    low = -1.0
    high = 1.0
    digits = 3

    [variants.fixed.correct]     # an id with fixed parameters (the examples)
    n = 7

or ``fixed = ["solution", "template"]``: ids graded with the instructor's values, the
parameters cell of the instructor notebook as written (plain literals: ``n = 7``).

A ``variants.py`` beside ``assignment.toml`` may define ``draw(rng) -> dict`` (more
parameters, drawn after the table's) and ``answers(params) -> dict`` (the expected
value of each varied quantity, used to see answers that travel). It runs on the
trusted side only; the folder is never readable by student code.

The seed of a student is an HMAC of the assignment name and the student id keyed by
the course secret: without the secret a student cannot compute a classmate's variant.
With no secret set, variants are off: every id is graded with the instructor's values
(the notebook as ``autograder release`` writes it without ``--variants``), and
``release --variants`` refuses to draw.
"""

from __future__ import annotations

import ast
import csv
import functools
import hashlib
import hmac
import importlib.util
import json
import os
import pprint
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Mapping, Sequence

import nbformat
import numpy as np

from autograder.errors import AssignmentError

__all__ = ["Variant", "VariantSpec", "parse_variants", "read_roster", "parameters_source",
           "travel_evidence", "instructor_values", "submitted_values", "cell_evidence",
           "VARIANT_TAG"]

VARIANT_TAG = "variant"
_KEYS = ("params", "roster", "cell", "secret_env", "fixed")
_KINDS = {"int": ("low", "high"), "float": ("low", "high", "digits"), "choice": ("values",),
          "points": ("n", "low", "high", "digits")}
_ROSTER_COLUMNS = ("student", "id", "login", "github_username", "identifier")
#: relative and absolute tolerance for "this output equals that variant's answer"
TRAVEL_RTOL, TRAVEL_ATOL = 1e-6, 1e-9


@dataclass(frozen=True)
class Variant:
    """One student's parameters, the seed they were drawn from, and who they belong to."""

    student: str
    #: None: not drawn (a fixed id, or the instructor's values because no secret is set)
    seed: int | None
    params: tuple[tuple[str, Any], ...]

    def __getitem__(self, name: str) -> Any:
        return dict(self.params)[name]

    def as_dict(self) -> dict[str, Any]:
        return dict(self.params)

    def to_dict(self) -> dict[str, Any]:
        return {"student": self.student, "seed": self.seed, "params": dict(self.params)}


@dataclass(frozen=True)
class VariantSpec:
    """The ``[variants]`` table of an assignment and its optional ``variants.py`` hook."""

    root: Path
    params: tuple[tuple[str, dict[str, Any]], ...] = ()
    roster: Path | None = None
    cell: str = VARIANT_TAG
    secret_env: str = "NUMGRADE_VARIANT_SECRET"
    fixed: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    hook: Path | None = field(default=None, compare=False)
    #: the parameters cell of the instructor notebook as written
    instructor: tuple[tuple[str, Any], ...] = ()

    def active(self) -> bool:
        """Whether the course secret is set: without it every id gets the instructor's values."""
        return bool(os.environ.get(self.secret_env, ""))

    def seed(self, assignment: str, student: str) -> int:
        secret = os.environ.get(self.secret_env, "").encode()
        digest = hmac.new(secret, f"{assignment}\0{student}".encode(), hashlib.sha256).digest()
        return int.from_bytes(digest[:8], "big")

    def draw(self, assignment: str, student: str) -> Variant:
        """``student``'s variant, whether or not the student is on the roster."""
        fixed = dict(self.fixed)
        if student in fixed:
            return Variant(student, None, fixed[student])
        if not self.active():
            return Variant(student, None, self.instructor)
        seed = self.seed(assignment, student)
        hook = self.hook if self.hook is not None and self.hook.is_file() else None
        drawn = _drawn(json.dumps(self.params, default=str), str(hook) if hook else "",
                       hook.stat().st_mtime_ns if hook else 0, seed)
        return Variant(student, seed, tuple(json.loads(drawn).items()))

    def students(self) -> tuple[str, ...] | None:
        """The roster's ids (``None``: no roster, every id has a variant)."""
        return None if self.roster is None else read_roster(self.roster)

    def lookup(self, assignment: str, student: str) -> Variant | None:
        """``student``'s variant, or ``None`` when a roster is declared and they are not on it
        (with no secret set, everyone's is the instructor's values)."""
        if not self.active():
            return self.draw(assignment, student)
        roster = self.students()
        if roster is not None and student not in roster and student not in dict(self.fixed):
            return None
        return self.draw(assignment, student)

    def answers(self, variant: Variant) -> dict[str, Any]:
        """The hook's expected varied quantities for ``variant`` (empty without ``answers``)."""
        module = _hook(self.hook)
        if module is None or not hasattr(module, "answers"):
            return {}
        found = module.answers(variant.as_dict())
        return dict(found) if isinstance(found, Mapping) else {}


@functools.lru_cache(maxsize=4096)
def _drawn(params: str, hook: str, mtime: int, seed: int) -> str:
    """The parameters drawn from ``seed`` (the table's, then the hook's), as JSON.

    Cached: every submission's evidence draws the whole roster's variants again, and a
    hook may take milliseconds per draw (the hull's redraws until a board is fair). The
    hook's modification time is in the key, so an edited hook draws afresh; JSON keeps
    the cached values from being changed by a caller.
    """
    rng = np.random.default_rng(seed)
    drawn = {name: _draw_one(rng, spec) for name, spec in json.loads(params)}
    module = _hook(Path(hook)) if hook else None
    if module is not None and hasattr(module, "draw"):
        extra = module.draw(rng)
        if not isinstance(extra, dict):
            raise AssignmentError(f"{hook}: draw(rng) must return a dict of "
                                  f"parameters; got {type(extra).__name__}.")
        drawn.update(extra)
    try:
        return json.dumps({k: _plain(v) for k, v in drawn.items()})
    except TypeError as exc:
        raise AssignmentError(f"{hook or 'the [variants] table'}: the parameters must be plain "
                              f"values (numbers, strings, lists of them): {exc}.") from None


def _draw_one(rng: np.random.Generator, spec: dict[str, Any]) -> Any:
    kind = spec["kind"]
    if kind == "int":
        return int(rng.integers(spec["low"], spec["high"], endpoint=True))
    if kind == "float":
        return round(float(rng.uniform(spec["low"], spec["high"])), int(spec.get("digits", 6)))
    if kind == "choice":
        return spec["values"][int(rng.integers(len(spec["values"])))]
    points = rng.uniform(spec.get("low", 0.0), spec.get("high", 1.0), size=(int(spec["n"]), 2))
    return np.round(points, int(spec.get("digits", 6))).tolist()


def _plain(value: Any) -> Any:
    """A parameter as plain data (numpy scalars and arrays to Python numbers and lists)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


_HOOKS: dict[tuple[str, int], ModuleType] = {}


def _hook(path: Path | None) -> ModuleType | None:
    """The assignment's ``variants.py``, imported once per modification time."""
    if path is None or not path.is_file():
        return None
    key = (str(path), path.stat().st_mtime_ns)
    if key not in _HOOKS:
        spec = importlib.util.spec_from_file_location(f"numgrade_variants_{abs(hash(key))}", path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _HOOKS[key] = module
    return _HOOKS[key]


def read_roster(path: Path) -> tuple[str, ...]:
    """The student ids of a roster CSV (GitHub Classroom's, or any with an id column)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            rows = list(csv.DictReader(handle))
    except OSError as exc:
        raise AssignmentError(f"The roster {path} could not be read ({exc.strerror}); "
                              "check the path given for the variants' roster.") from None
    header = [h.strip().lower() for h in (rows[0].keys() if rows else [])]
    column = next((c for c in _ROSTER_COLUMNS if c in header), None)
    if column is None:
        raise AssignmentError(f"The roster {path} needs a column named one of "
                              f"{', '.join(_ROSTER_COLUMNS)} (the student's id); its columns: "
                              f"{', '.join(header) or 'none'}.")
    original = next(k for k in rows[0] if k.strip().lower() == column)
    return tuple(dict.fromkeys(r[original].strip() for r in rows if (r[original] or "").strip()))


def parse_variants(root: Path, toml_path: Path, table: Any,
                   notebook: Path | None = None) -> VariantSpec | None:
    """The ``[variants]`` table checked (every mistake names the key and the fix).

    ``notebook``: the instructor notebook, whose parameters cell gives the instructor's
    values (ids in a ``fixed`` list, and everyone when no secret is set).
    """
    hook = root / "variants.py"
    if table is None:
        return None
    if not isinstance(table, dict):
        raise AssignmentError(f"{toml_path}: 'variants' must be a table ([variants]).")
    unknown = sorted(set(table) - set(_KEYS))
    if unknown:
        raise AssignmentError(f"{toml_path}: unknown key(s) {unknown} in [variants]; "
                              f"allowed keys: {list(_KEYS)}.")
    params = tuple((name, _param(toml_path, name, spec))
                   for name, spec in dict(table.get("params", {})).items())
    if not params and not hook.is_file():
        raise AssignmentError(f"{toml_path}: [variants] declares no parameter: add "
                              "[variants.params.NAME] tables or a variants.py with draw(rng).")
    roster = table.get("roster")
    if roster is not None:
        roster = (root / str(roster)).resolve()
        if not roster.is_file():
            raise AssignmentError(f"{toml_path}: [variants] roster {table['roster']!r} was not "
                                  f"found in {root}; give a CSV of student ids.")
    cell = str(table.get("cell", VARIANT_TAG))
    instructor = instructor_values(notebook, cell) if notebook is not None else ()
    given = table.get("fixed", {})
    if isinstance(given, list):  # ids graded with the instructor's values
        if not instructor:
            raise AssignmentError(f"{toml_path}: [variants] fixed = [...] grades those ids "
                                  "with the instructor's values, and the instructor notebook "
                                  f"has no code cell tagged {cell!r} setting them; tag the "
                                  "parameters cell, or give [variants.fixed.ID] tables.")
        fixed = tuple((str(student), instructor) for student in given)
    elif isinstance(given, dict):
        fixed = tuple((str(student), tuple((str(k), v) for k, v in dict(values).items()))
                      for student, values in given.items())
    else:
        raise AssignmentError(f"{toml_path}: [variants] fixed must be a list of ids (graded "
                              "with the instructor notebook's values) or tables "
                              "[variants.fixed.ID] of parameters.")
    return VariantSpec(root=root, params=params, roster=roster, cell=cell,
                       secret_env=str(table.get("secret_env", "NUMGRADE_VARIANT_SECRET")),
                       fixed=fixed, hook=hook if hook.is_file() else None,
                       instructor=instructor)


def instructor_values(notebook: Path, cell: str) -> tuple[tuple[str, Any], ...]:
    """The parameters cell (tagged ``cell``) of the instructor notebook: ``name = literal``
    lines, read with :func:`ast.literal_eval` (never run). Empty without such a cell."""
    try:
        source = _cell_source(notebook, cell)
    except Exception:  # nbformat raises many types; load_assignment reports a bad notebook
        return ()
    if source is None:
        return ()
    try:
        return tuple(_literal_lines(source).items())
    except SyntaxError as exc:
        raise AssignmentError(f"{notebook}: the parameters cell (tagged {cell!r}) is not "
                              f"valid Python (line {exc.lineno}: {exc.msg}).") from None
    except ValueError as exc:
        raise AssignmentError(
            f"{notebook}: the parameters cell (tagged {cell!r}) may only set names to "
            f"plain values (numbers, strings, lists), one `name = value` per line; line "
            f"{exc.args[0]} is not one.") from None


#: a submitted parameters cell longer than this is not read (a point set of 31 pins is 1 KB)
MAX_SUBMITTED_CELL = 200_000


def submitted_values(notebook: Path | None, cell: str, *, max_bytes: int) -> dict[str, Any] | None:
    """The values of a submitted notebook's parameters cell, read with :func:`ast.literal_eval`
    on the grader's side (never run); ``None`` when it has none or they are not plain values.

    A file over ``max_bytes`` (the grader's notebook limit, which refuses it anyway) is not
    read: the size is checked before nbformat parses anything a student sent.
    """
    try:
        if notebook is None or notebook.stat().st_size > max_bytes:
            return None
        source = _cell_source(notebook, cell)
        if source is None or len(source) > MAX_SUBMITTED_CELL:
            return None
        return _literal_lines(source)
    except Exception:  # anything a student wrote (deep nesting included): no evidence
        return None


def _cell_source(notebook: Path, cell: str) -> str | None:
    # Not nbformat.read: its schema validation only logs (the grader validates the notebook
    # itself, in engine/notebook.py) and, with its NotebookNode of every cell, it took
    # seconds on a notebook of many cells. A version 4 file is read as plain JSON; an
    # older one goes through nbformat's conversion.
    book = nbformat.reader.parse_json(notebook.read_text(encoding="utf-8"))
    if nbformat.reader.get_version(book)[0] != 4:
        book = nbformat.convert(nbformat.reader.reads(json.dumps(book)), 4)
    found = [c for c in book["cells"] if c.get("cell_type") == "code"
             and cell in c.get("metadata", {}).get("tags", [])]
    if len(found) != 1:
        return None
    source = found[0].get("source", "")
    return source if isinstance(source, str) else "".join(source)


def _literal_lines(source: str) -> dict[str, Any]:
    """``name = literal`` lines as a dict; ValueError(line number) for any other line."""
    values: dict[str, Any] = {}
    for node in ast.parse(source).body:
        target = node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 \
            else None
        if not isinstance(target, ast.Name):
            raise ValueError(node.lineno)
        try:
            values[target.id] = ast.literal_eval(node.value)  # type: ignore[union-attr]
        except ValueError:
            raise ValueError(node.lineno) from None
    return values


def cell_evidence(own: Variant, submitted: Mapping[str, Any] | None, others: Sequence[Variant],
                  *, secret_env: str, active: bool) -> list[str]:
    """Why the submitted notebook's parameters cell is not the student's own, one line each:
    a classmate's variant (a copied notebook), or values nobody was given."""
    if submitted is None or not own.params:
        return []

    def holds(variant: Variant) -> bool:
        return all(k in submitted and _same(submitted[k], v) for k, v in variant.params)

    if holds(own):
        return []
    for other in others:
        if other.student != own.student and other.params != own.params and holds(other):
            return [f"the notebook's parameters cell holds {other.student}'s variant, not this "
                    f"student's (a notebook copied from {other.student}, or handed on)"]
    if not active:
        return [f"the notebook's parameters cell holds values that are not the instructor's, "
                f"and {secret_env} is not set here, so it was graded with the instructor's "
                "values; if it was released with --variants, set the course secret and grade "
                "again"]
    return ["the notebook's parameters cell holds values other than this student's variant "
            "(changed by hand, or released under another course secret)"]


def _param(toml_path: Path, name: str, spec: Any) -> dict[str, Any]:
    where = f"{toml_path}: [variants.params.{name}]"
    if not isinstance(spec, dict) or spec.get("kind") not in _KINDS:
        raise AssignmentError(f"{where} needs kind = one of {', '.join(_KINDS)}.")
    if not name.isidentifier():
        raise AssignmentError(f"{where}: the name must be a Python identifier (it becomes a "
                              "variable in the student's notebook).")
    kind = spec["kind"]
    required = {"int": ("low", "high"), "float": ("low", "high"), "choice": ("values",),
                "points": ("n",)}[kind]
    missing = [k for k in required if k not in spec]
    stray = sorted(set(spec) - {"kind", *_KINDS[kind]})
    if missing or stray:
        raise AssignmentError(f"{where}: kind {kind!r} needs {', '.join(required)} and allows "
                              f"{', '.join(_KINDS[kind])}; missing {missing}, unknown {stray}.")
    if kind == "choice" and (not isinstance(spec["values"], list) or not spec["values"]):
        raise AssignmentError(f"{where}: values must be a non-empty list.")
    if kind in ("int", "float") and not spec["low"] <= spec["high"]:
        raise AssignmentError(f"{where}: low must not exceed high.")
    return dict(spec)


def parameters_source(variant: Variant) -> str:
    """The parameters cell of ``variant``'s notebook: one assignment per parameter."""
    lines = [f"# Your parameters (drawn for {variant.student}). Do not change them: the "
             "grader uses these values."]
    # pprint breaks long lists (a point set) over lines; the text stays a Python literal
    lines += [f"{name} = {pprint.pformat(value, width=88, compact=True)}"
              for name, value in variant.params]
    return "\n".join(lines) + "\n"


def _same(a: Any, b: Any) -> bool:
    try:
        x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    except (TypeError, ValueError):
        return bool(a == b)
    return x.shape == y.shape and bool(np.allclose(x, y, rtol=TRAVEL_RTOL, atol=TRAVEL_ATOL))


def travel_evidence(own: Variant, observed: Mapping[str, Any], others: Sequence[Variant],
                    answers: Callable[[Variant], dict[str, Any]]) -> list[str]:
    """Why the outputs ``observed`` look like another student's answers, one line each.

    A quantity counts when it differs from ``own``'s expected value and equals the
    expected value of a classmate's variant (whose parameters differ from ``own``'s).
    """
    mine = answers(own)
    found = []
    for other in others:
        if other.student == own.student or other.params == own.params:
            continue
        theirs = answers(other)
        for name, value in observed.items():
            if name in theirs and name in mine and not _same(value, mine[name]) \
                    and _same(value, theirs[name]):
                found.append(f"{name} = {_short(value)} is the answer of {other.student}'s "
                             f"variant{_params(other)}, not of this student's"
                             f"{_params(own)} (expected {_short(mine[name])})")
    return found


def _params(variant: Variant) -> str:
    """`` (a=3)``: a variant's parameters when they are short enough to read in a line
    (a point set of 31 pins is not: the variant's owner names it)."""
    text = ", ".join(f"{k}={_short(v)}" for k, v in variant.params)
    return f" ({text})" if len(text) <= 60 else ""


def _short(value: Any) -> str:
    value = _plain(value)
    try:  # outputs are recorded as floats: indices 3.0, 7.0 read better as 3, 7
        array = np.asarray(value, dtype=float)
        if array.size and np.all(np.isfinite(array)) and np.all(array == np.round(array)) \
                and np.all(np.abs(array) < 2**53):
            value = array.astype(np.int64).tolist()
    except (TypeError, ValueError):
        pass
    text = repr(value)
    return text if len(text) <= 120 else text[:117] + "..."
