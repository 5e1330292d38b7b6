"""The house rules of the source tree, read from the code itself.

The folders of ``autograder/`` are rooms by trust level (docs/design.md). Which
room may import which is written once, in ``MAY_IMPORT``, and this test reads
every import statement of every module (top level and inside functions alike)
and fails on:

- an import a room is not allowed (the worker importing the engine, the
  sandbox importing the worker, ``reference`` and the engine importing each other);
- a circle of modules importing each other, anywhere (a package's ``__init__``
  counts as a module of its own);
- an import of an ``autograder`` module that does not exist;
- a module over 800 lines or a function over 80 (docstrings not counted), and
  more than six modules directly in ``autograder/``.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("autograder", "reference")

#: room -> the rooms it may import besides itself. A room is a folder of
#: ``autograder/`` or one of its top-level modules; ``autograder`` is the package's
#: ``__init__`` (which imports nothing, see below).
MAY_IMPORT: dict[str, frozenset[str]] = {
    "errors": frozenset(),
    "boundary": frozenset({"errors"}),
    "sandbox": frozenset({"boundary", "errors"}),
    # the untrusted process: the boundary and the sandbox, nothing of the grader
    "worker": frozenset({"boundary", "sandbox", "errors"}),
    "results": frozenset({"errors"}),
    "engine": frozenset({"boundary", "sandbox", "results", "errors"}),
    "checks": frozenset({"engine", "results", "boundary", "errors"}),
    "runners": frozenset({"engine", "results", "sandbox", "boundary", "errors"}),
    "authoring": frozenset({"runners", "engine", "checks", "results", "errors"}),
    "service": frozenset({"runners", "engine", "results", "errors"}),
    "api": frozenset({"authoring", "runners", "engine", "checks", "results", "errors"}),
    # check() and submit() in a student's notebook: the API's check, the upload client
    "student": frozenset({"api", "service", "results", "errors"}),
    "cli": frozenset({"api", "service", "authoring", "runners", "engine", "results",
                      "sandbox", "errors"}),
    "__main__": frozenset({"cli"}),
}
#: modules every room may import: the package root, which imports nothing itself
EVERYONE_MAY_IMPORT = frozenset({"autograder"})

MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 80
MAX_TOP_LEVEL_MODULES = 6


def module_files() -> dict[str, Path]:
    """Dotted name -> file, for every module of the two packages."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


MODULES = module_files()


def imports_of(name: str, path: Path) -> Iterator[tuple[int, str]]:
    """(line, dotted module) of every import in ``path``, relative ones resolved."""
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".")
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                full = f"{module}.{alias.name}"
                yield node.lineno, full if full in MODULES else module


def internal_edges() -> dict[str, set[tuple[int, str]]]:
    edges: dict[str, set[tuple[int, str]]] = {}
    for name, path in MODULES.items():
        edges[name] = {(line, target) for line, target in imports_of(name, path)
                       if target.split(".")[0] in PACKAGES and target != name}
    return edges


EDGES = internal_edges()


def room(module: str) -> str:
    """The room of an ``autograder`` module: its folder, or its own name at the top."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "autograder"


def test_every_room_is_listed() -> None:
    rooms = {room(m) for m in MODULES if m.startswith("autograder.")}
    assert rooms <= set(MAY_IMPORT), f"rooms with no rule in MAY_IMPORT: {rooms - set(MAY_IMPORT)}"


def test_rooms_import_only_what_they_may() -> None:
    wrong = []
    for name, targets in EDGES.items():
        if not name.startswith("autograder."):
            continue
        mine = room(name)
        for line, target in sorted(targets):
            theirs = room(target) if target.startswith("autograder") else target.split(".")[0]
            allowed = {mine} | MAY_IMPORT[mine] | EVERYONE_MAY_IMPORT
            if target.startswith("reference") or (theirs not in allowed and target != "autograder"):
                wrong.append(f"{MODULES[name].relative_to(ROOT)}:{line}: {mine} imports {target}")
    assert not wrong, "imports across the rooms' rules:\n" + "\n".join(wrong)


def test_the_package_root_and_the_exceptions_import_nothing_of_the_package() -> None:
    for name in ("autograder", "autograder.errors"):
        assert not EDGES[name], f"{name} imports {sorted(t for _, t in EDGES[name])}"


def test_reference_knows_nothing_of_grading() -> None:
    wrong = [f"{name} imports {target}" for name, targets in EDGES.items()
             if name.startswith("reference") for _, target in targets
             if target.startswith("autograder")]
    assert not wrong


def test_every_imported_module_exists() -> None:
    missing = [f"{MODULES[name].relative_to(ROOT)}:{line}: {target}"
               for name, targets in EDGES.items() for line, target in sorted(targets)
               if target not in MODULES]
    assert not missing, "imports of modules that do not exist:\n" + "\n".join(missing)


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for start in edges:
        if start in index:
            continue
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            for child in children:
                if child not in edges:
                    continue
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                    break
                if child in on_stack:
                    low[node] = min(low[node], index[child])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    group = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        group.append(member)
                        if member == node:
                            break
                    if len(group) > 1:
                        found.append(sorted(group))
    return found


def test_circle_finder_finds_a_circle() -> None:
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


def test_no_two_modules_import_each_other() -> None:
    found = circles({name: {t for _, t in targets} for name, targets in EDGES.items()})
    assert not found, "modules that import each other: " + "; ".join(" <-> ".join(c) for c in found)


def test_at_most_six_modules_directly_in_autograder() -> None:
    top = sorted(p.name for p in (ROOT / "autograder").glob("*.py"))
    assert len(top) <= MAX_TOP_LEVEL_MODULES, top


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_and_functions_are_short_enough_to_read(name: str) -> None:
    path = MODULES[name]
    text = path.read_text(encoding="utf-8")
    assert text.count("\n") <= MAX_MODULE_LINES, \
        f"{path.relative_to(ROOT)} has {text.count(chr(10))} lines; split it by job"
    long = []
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines = node.end_lineno - node.lineno + 1  # type: ignore[operator]
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                lines -= first.end_lineno - first.lineno + 1  # type: ignore[operator]
            if lines > MAX_FUNCTION_LINES:
                long.append(f"{node.name} (line {node.lineno}): {lines} lines")
    assert not long, f"{path.relative_to(ROOT)}: functions over {MAX_FUNCTION_LINES} lines: {long}"


def test_an_edit_that_breaks_a_rule_is_caught(tmp_path: Path) -> None:
    """The rule test can fail: a worker module importing the engine is reported."""
    source = "from autograder.engine.grader import Grader\n"
    path = tmp_path / "bad.py"
    path.write_text(source)
    targets = {t for _, t in imports_of("autograder.worker.bad", path)}
    assert targets == {"autograder.engine.grader"}
    assert room("autograder.engine.grader") not in MAY_IMPORT["worker"]
