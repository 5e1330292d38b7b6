"""Find uses of forbidden names in submitted code, without running it.

This runs in the trusted process, on the cells' text only. Each cell is turned
from IPython syntax into Python with IPython's own ``TransformerManager`` (so
``%magics`` and ``!commands`` parse; see :mod:`autograder.engine.scanipython`),
then walked with :mod:`ast`; what the walk finds is reported as
:class:`~autograder.engine.scanfindings.ScanFindings`:

* **Names are resolved through imports and aliases.** ``import scipy.spatial as
  sp; sp.ConvexHull``, ``from scipy.spatial import ConvexHull as CH``,
  ``from scipy import spatial``, ``import scipy; scipy.spatial.Delaunay``,
  ``H = sp.ConvexHull``, ``getattr(sp, "ConvexHull")``,
  ``importlib.import_module("scipy.spatial")`` and star imports all resolve to
  dotted names such as ``scipy.spatial.ConvexHull``.
* **Matching.** A forbidden ``"scipy.spatial"`` matches itself and any name
  under it; ``"scipy.interpolate.CubicSpline"`` matches that name, names under
  it, and submodule-qualified forms such as
  ``scipy.interpolate._cubic.CubicSpline``.
* **Scopes.** Module-level code is read in order (a later rebinding hides an
  earlier import). Function and class bodies run when called, after the whole
  notebook ran, so their global names resolve against the module's final
  state. Local names (parameters, assignments) shadow globals.
* **Taint.** Each top-level name (function, class, or variable) is tainted when
  its body, decorators or value use a forbidden name, or when it is itself
  bound to a forbidden name (``from scipy.spatial import ConvexHull as hull``);
  taint then flows through references between top-level names (the call
  graph) to a fixed point. An import at module level is a use, but taints no
  function that does not itself use the name.
* **Dynamic code.** ``exec``, ``eval``, ``compile``, ``__import__`` and
  ``importlib.import_module`` with a computed name, ``getattr`` on a module
  with a computed name, ``runpy``, ``%run``, ``%%writefile`` and
  ``get_ipython().ex/run_cell/...`` cannot be verified: they are reported in
  :attr:`~autograder.engine.scanfindings.ScanFindings.dynamic`, and the
  top-level names reaching them in
  :attr:`~autograder.engine.scanfindings.ScanFindings.unverified`.
* **Magics that run Python** (``%time``, ``%timeit``, ``%prun``, ``%debug``,
  ``%%time``, ``%%timeit``, ``%%capture``, ``%%prun``, ``%%debug``) have their
  code scanned as if written in the cell.
"""

from __future__ import annotations

import ast
import builtins
import re
from dataclasses import dataclass, field, replace
from typing import Callable, Iterable, Sequence

from autograder.engine.scanfindings import ScanFindings, Use
from autograder.engine.scanipython import CellParser, ipython_call
from autograder.errors import UsageError

__all__ = ["scan"]

_DOTTED = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")
_BUILTINS = frozenset(dir(builtins)) | {"get_ipython", "display", "__builtins__"}
_GET_IPYTHON = frozenset({"builtins.get_ipython", "IPython.get_ipython",
                          "IPython.core.getipython.get_ipython"})
_IMPORT_FUNCS = frozenset({"builtins.__import__", "importlib.import_module",
                           "importlib.__import__"})
_EXEC_FUNCS = frozenset({"builtins.exec", "builtins.eval", "builtins.compile",
                         "runpy.run_path", "runpy.run_module"})
#: attributes that reach objects by their links instead of their names (a class's
#: subclasses, a function's closure and globals, frames): the worker's guard refuses
#: what it can on these routes, and a person looks at the rest
_DIGGING_ATTRS = frozenset({"__subclasses__", "__closure__", "cell_contents", "__globals__",
                            "__wrapped__", "__code__", "f_back", "f_locals", "f_globals",
                            "tb_frame", "gi_frame", "_getframe", "_current_frames",
                            "settrace", "setprofile", "get_referents", "get_referrers",
                            "get_objects", "__builtins__", "__self__"})
#: modules whose every use is a route around names
_DIGGING_MODULES = ("ctypes", "gc")
_TEXT_LIMIT = 200
_COMPREHENSIONS = (ast.ListComp, ast.SetComp, ast.DictComp, ast.GeneratorExp)
_NESTED_SCOPES = (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda,
                  *_COMPREHENSIONS)


def scan(sources: Sequence[str], forbid: Sequence[str]) -> ScanFindings:
    """Scan code cells for uses of forbidden names.

    Parameters
    ----------
    sources : sequence of str
        The code cells, in order (IPython syntax allowed).
    forbid : sequence of str
        Dotted names: modules (``"scipy.spatial"``) or attributes
        (``"scipy.interpolate.CubicSpline"``).

    Returns
    -------
    ScanFindings

    Raises
    ------
    UsageError
        When a ``forbid`` entry is not a dotted name (a grader setting), or a
        source is not a string.

    Examples
    --------
    >>> report = scan(["import scipy.spatial as sp",
    ...                "def hull(p):\\n    return sp.ConvexHull(p)"], ["scipy.spatial"])
    >>> sorted(report.tainted), [(u.function, u.cell, u.line) for u in report.uses]
    (['hull', 'sp'], [(None, 0, 1), ('hull', 1, 2)])
    """
    analyzer = _Analyzer(_checked_forbid(forbid))
    for index, source in enumerate(sources):
        if not isinstance(source, str):
            raise UsageError(f"`sources` must hold strings; item {index} is "
                             f"{type(source).__name__}.")
        analyzer.add_cell(index, source)
    return analyzer.report()


def _checked_forbid(forbid: Sequence[str]) -> tuple[str, ...]:
    if isinstance(forbid, str):
        raise UsageError(f"`forbid` must be a list of dotted names; got the string {forbid!r}.")
    for name in forbid:
        if not isinstance(name, str) or not _DOTTED.match(name):
            raise UsageError(f"`forbid` entries must be dotted names such as 'scipy.spatial'; "
                             f"got {name!r}.")
    return tuple(forbid)


def _matches(qual: str, forbid: tuple[str, ...]) -> str | None:
    """The entry of ``forbid`` that ``qual`` falls under, or None."""
    for entry in forbid:
        if qual == entry or qual.startswith(entry + "."):
            return entry
        parent, _, attr = entry.rpartition(".")
        if parent and qual.startswith(parent + "."):
            rest = qual[len(parent) + 1:].split(".")
            if attr in rest[1:]:  # submodule-qualified: parent._private.attr
                return entry
    return None


# -- internal state (mutable, private to one scan) ---------------------------------

@dataclass
class _Sink:
    """What one top-level definition (or one module-level statement) touches."""

    direct: bool = False
    dynamic: bool = False
    refs: set[str] = field(default_factory=set)


@dataclass
class _Def:
    """The current binding of a module-level name."""

    qual: str | None
    sink: _Sink


@dataclass
class _Scope:
    """A function, class, lambda or comprehension scope."""

    bindings: dict[str, str | None]
    globals: frozenset[str] = frozenset()
    nonlocals: frozenset[str] = frozenset()
    kind: str = "function"  # "function", "class" or "comprehension"


@dataclass(frozen=True)
class _Where:
    """Maps line numbers of (possibly nested) parsed code to the cell's lines."""

    cell: int
    lines: tuple[str, ...]
    base: int = 0
    fixed: int | None = None

    def line(self, node: ast.AST | None = None) -> int:
        """The cell line of ``node`` (of the code's first line when None)."""
        if self.fixed is not None:
            return self.fixed
        return self.base + getattr(node, "lineno", 1)

    def text(self, line: int) -> str:
        """The stripped source line, shortened to :data:`_TEXT_LIMIT` characters."""
        text = self.lines[line - 1].strip() if 1 <= line <= len(self.lines) else ""
        return text if len(text) <= _TEXT_LIMIT else text[: _TEXT_LIMIT - 3] + "..."


@dataclass(frozen=True)
class _Ctx:
    where: _Where
    scopes: tuple[_Scope, ...]
    owner: str | None
    sink: _Sink


#: statements (top level and in function bodies) the scan walks before it stops
MAX_STATEMENTS = 50_000


class _Analyzer:
    """One scan: module state, deferred bodies, findings."""

    def __init__(self, forbid: tuple[str, ...]) -> None:
        self.forbid = forbid
        self.module: dict[str, _Def] = {}
        self.star_forbidden: list[str] = []
        self.deferred: list[tuple[ast.AST, _Ctx]] = []
        self.uses: list[Use] = []
        self.dynamic: list[Use] = []
        self.errors: list[str] = []
        self.parser = CellParser()
        #: statements walked so far; past MAX_STATEMENTS the scan stops (a count, not a
        #: clock, so the same code always gets the same report)
        self.statements = 0

    # -- cells and parsing ---------------------------------------------------------

    def add_cell(self, index: int, source: str) -> None:
        where = _Where(cell=index, lines=tuple(source.splitlines()))
        self._run_code(source, _Ctx(where, (), None, _Sink()), label="")

    def _parse(self, source: str, where: _Where, label: str) -> ast.Module | None:
        try:
            return self.parser.parse(source)
        except SyntaxError as exc:
            line = where.fixed if where.fixed is not None else where.base + (exc.lineno or 1)
            self._error(where, line, f"{exc.msg}{label}")
        except RecursionError:
            # Where the parser gives up depends on the Python version (3.11.2 stops
            # in ast.parse where 3.11.7 parses and the walk stops): one message for both.
            self._error(where, where.line(), f"too deeply nested to check{label}")
        except (ValueError, MemoryError) as exc:
            self._error(where, where.line(), f"cannot be parsed "
                        f"({type(exc).__name__}){label}")
        except Exception as exc:  # IPython's transformer on odd input
            self._error(where, where.line(), f"IPython syntax could not be "
                        f"converted ({type(exc).__name__}){label}")
        return None

    def _error(self, where: _Where, line: int, message: str) -> None:
        self.errors.append(f"cell {where.cell}, line {line}: {message}")

    def _run_code(self, source: str, ctx: _Ctx, label: str) -> None:
        tree = self._parse(source, ctx.where, label)
        if tree is not None:
            for stmt in tree.body:
                self._guarded(self._stmt, stmt, ctx)

    def _guarded(self, step: Callable[[ast.AST, _Ctx], None], node: ast.AST,
                 ctx: _Ctx) -> None:
        """Run ``step(node, ctx)``; code too deep or too long to walk becomes unverifiable."""
        self.statements += 1
        if self.statements == MAX_STATEMENTS + 1:
            self._error(ctx.where, ctx.where.line(node), f"the scan stopped after "
                        f"{MAX_STATEMENTS} statements; the rest was not checked")
            self._dynamic("<not scanned: too long>", node, ctx)
        if self.statements > MAX_STATEMENTS:
            return
        try:
            step(node, ctx)
        except RecursionError:
            line = ctx.where.line(node)
            self._error(ctx.where, line, "too deeply nested to check")
            self._dynamic("<too deeply nested>", node, ctx)

    # -- findings ------------------------------------------------------------------

    def _use(self, name: str, node: ast.AST, ctx: _Ctx) -> Use:
        line = ctx.where.line(node)
        return Use(name=name, function=ctx.owner, cell=ctx.where.cell, line=line,
                   text=ctx.where.text(line))

    def _check(self, qual: str, node: ast.AST, ctx: _Ctx) -> None:
        digging = _matches(qual, _DIGGING_MODULES)
        if digging is not None:
            self._dynamic(digging, node, ctx)
        entry = _matches(qual, self.forbid)
        if entry is not None:
            self.uses.append(self._use(entry, node, ctx))
            ctx.sink.direct = True

    def _dynamic(self, name: str, node: ast.AST, ctx: _Ctx) -> None:
        self.dynamic.append(self._use(name, node, ctx))
        ctx.sink.dynamic = True

    # -- binding and resolving names ---------------------------------------------

    def _bind(self, name: str, qual: str | None, ctx: _Ctx) -> None:
        if ctx.scopes:
            scope = ctx.scopes[-1]
            if name not in scope.globals:
                scope.bindings[name] = qual
                return
            if qual is None:
                return
            ctx = replace(ctx, sink=_Sink())
        self.module[name] = _Def(qual, ctx.sink)

    def _lookup(self, name: str, scopes: tuple[_Scope, ...],
                sink: _Sink | None = None) -> str | None:
        """The dotted name ``name`` stands for; records module references in ``sink``."""
        for depth, scope in enumerate(reversed(scopes)):
            if name in scope.globals:
                break
            if name in scope.nonlocals or (scope.kind == "class" and depth > 0):
                continue
            if name in scope.bindings:
                return scope.bindings[name]
        if sink is not None:
            sink.refs.add(name)
        if name in self.module:
            return self.module[name].qual
        if name in _BUILTINS:
            return "builtins" if name == "__builtins__" else f"builtins.{name}"
        if self.star_forbidden:
            return f"{self.star_forbidden[-1]}.{name}"
        return None

    def _qualify(self, node: ast.AST, scopes: tuple[_Scope, ...]) -> str | None:
        """The dotted name an expression stands for, or None (no side effects)."""
        attrs: list[str] = []
        while isinstance(node, ast.Attribute):
            attrs.append(node.attr)
            node = node.value
        if isinstance(node, ast.Name):
            base = self._lookup(node.id, scopes)
        elif isinstance(node, ast.Call):
            base = self._call_qual(node, scopes)
        elif isinstance(node, ast.Subscript):
            base = self._subscript_qual(node, scopes)
        else:
            base = None
        return ".".join([base, *reversed(attrs)]) if base is not None else None

    def _call_qual(self, call: ast.Call, scopes: tuple[_Scope, ...]) -> str | None:
        func = self._qualify(call.func, scopes)
        if func in _GET_IPYTHON:
            return "get_ipython()"
        first = _literal_str(call.args[0]) if call.args else None
        if func in _IMPORT_FUNCS and first and not first.startswith("."):
            if func != "importlib.import_module" and not _has_fromlist(call):
                return first.split(".")[0]
            return first
        if func == "builtins.getattr" and len(call.args) >= 2:
            attr, base = _literal_str(call.args[1]), self._qualify(call.args[0], scopes)
            if attr and base and _DOTTED.match(attr):
                return f"{base}.{attr}"
        return None

    def _subscript_qual(self, node: ast.Subscript, scopes: tuple[_Scope, ...]) -> str | None:
        key = _literal_str(node.slice)
        if key and _DOTTED.match(key) and self._qualify(node.value, scopes) == "sys.modules":
            return key
        return None

    # -- statements ------------------------------------------------------------------

    def _stmts(self, body: Iterable[ast.stmt], ctx: _Ctx) -> None:
        for stmt in body:
            self._stmt(stmt, ctx)

    def _stmt(self, node: ast.stmt, ctx: _Ctx) -> None:
        if not ctx.scopes:  # each module-level statement has its own sink
            ctx = _Ctx(ctx.where, ctx.scopes, ctx.owner, _Sink())
        handler = getattr(self, f"_stmt_{type(node).__name__}", None)
        if handler is not None:
            handler(node, ctx)
        else:
            self._generic(node, ctx)

    def _generic(self, node: ast.AST, ctx: _Ctx) -> None:
        for _, value in ast.iter_fields(node):
            for item in value if isinstance(value, list) else [value]:
                if isinstance(item, ast.stmt):
                    self._stmt(item, ctx)
                elif isinstance(item, ast.AST):
                    self._expr(item, ctx)

    def _stmt_FunctionDef(self, node: ast.FunctionDef | ast.AsyncFunctionDef, ctx: _Ctx) -> None:
        args = node.args
        header = [*node.decorator_list, *args.defaults, *filter(None, args.kw_defaults)]
        self._define(node, header, ctx)

    _stmt_AsyncFunctionDef = _stmt_FunctionDef

    def _stmt_ClassDef(self, node: ast.ClassDef, ctx: _Ctx) -> None:
        header = [*node.decorator_list, *node.bases, *(k.value for k in node.keywords)]
        self._define(node, header, ctx)

    def _define(self, node: ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef,
                header: list[ast.expr], ctx: _Ctx) -> None:
        """Bind a def or class; its body is walked now (nested) or at the end (top level)."""
        for expr in header:
            self._expr(expr, ctx)
        if ctx.scopes:
            self._bind(node.name, None, ctx)
            self._body(node, ctx)
            return
        self.module[node.name] = _Def(None, ctx.sink)
        self.deferred.append((node, replace(ctx, owner=node.name)))

    def _body(self, node: ast.AST, ctx: _Ctx) -> None:
        """Walk a def or class body in a new scope (annotations are not uses)."""
        assert isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))
        bound, declared_global, declared_nonlocal = _local_names(node.body)
        kind = "function"
        if isinstance(node, ast.ClassDef):
            kind = "class"
        else:
            bound |= _parameters(node.args)
        scope = _Scope(bindings=dict.fromkeys(bound - declared_global - declared_nonlocal),
                       globals=frozenset(declared_global),
                       nonlocals=frozenset(declared_nonlocal), kind=kind)
        self._stmts(node.body, replace(ctx, scopes=(*ctx.scopes, scope)))

    def _stmt_Import(self, node: ast.Import, ctx: _Ctx) -> None:
        own = replace(ctx, sink=_Sink())  # an alias is tainted by what it names only
        for alias in node.names:
            self._check(alias.name, node, ctx)
            if alias.asname:
                self._bind(alias.asname, alias.name, own)
            else:
                top = alias.name.split(".")[0]
                self._bind(top, top, own)

    def _stmt_ImportFrom(self, node: ast.ImportFrom, ctx: _Ctx) -> None:
        module = node.module if not node.level else None
        for alias in node.names:
            if alias.name == "*":
                if module is not None:
                    self._star(module, node, ctx)
                continue
            qual = f"{module}.{alias.name}" if module else None
            if qual is not None:
                self._check(qual, node, ctx)
            self._bind(alias.asname or alias.name, qual, replace(ctx, sink=_Sink()))

    def _star(self, module: str, node: ast.ImportFrom, ctx: _Ctx) -> None:
        """``from module import *``: bind forbidden names it may bring in."""
        self._check(module, node, ctx)
        if _matches(module, self.forbid):
            self.star_forbidden.append(module)
        for entry in self.forbid:
            if entry.startswith(module + "."):
                name = entry[len(module) + 1:].split(".")[0]
                self._bind(name, f"{module}.{name}", replace(ctx, sink=_Sink()))

    def _stmt_Assign(self, node: ast.Assign, ctx: _Ctx) -> None:
        self._expr(node.value, ctx)
        single = len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)
        qual = self._qualify(node.value, ctx.scopes) if single else None
        for target in node.targets:
            self._target(target, qual, ctx)

    def _stmt_AnnAssign(self, node: ast.AnnAssign, ctx: _Ctx) -> None:
        if node.value is not None:
            self._expr(node.value, ctx)
            qual = self._qualify(node.value, ctx.scopes)
            self._target(node.target, qual if isinstance(node.target, ast.Name) else None, ctx)

    def _stmt_AugAssign(self, node: ast.AugAssign, ctx: _Ctx) -> None:
        self._expr(node.value, ctx)
        target = node.target
        if not isinstance(target, ast.Name):
            self._expr(target, ctx)
        elif not ctx.scopes and target.id in self.module:
            merged = self.module[target.id].sink
            merged.direct |= ctx.sink.direct
            merged.dynamic |= ctx.sink.dynamic
            merged.refs |= ctx.sink.refs | {target.id}
        elif not ctx.scopes:
            self.module[target.id] = _Def(None, ctx.sink)

    def _target(self, target: ast.expr, qual: str | None, ctx: _Ctx) -> None:
        if isinstance(target, ast.Name):
            self._bind(target.id, qual, ctx)
        elif isinstance(target, (ast.Tuple, ast.List)):
            for item in target.elts:
                self._target(item, None, ctx)
        elif isinstance(target, ast.Starred):
            self._target(target.value, None, ctx)
        else:  # attribute or subscript: an expression that may use names
            self._expr(target, ctx)

    def _stmt_For(self, node: ast.For | ast.AsyncFor, ctx: _Ctx) -> None:
        self._expr(node.iter, ctx)
        self._target(node.target, None, ctx)
        self._stmts(node.body, ctx)
        self._stmts(node.orelse, ctx)

    _stmt_AsyncFor = _stmt_For

    def _stmt_With(self, node: ast.With | ast.AsyncWith, ctx: _Ctx) -> None:
        for item in node.items:
            self._expr(item.context_expr, ctx)
            if item.optional_vars is not None:
                self._target(item.optional_vars, None, ctx)
        self._stmts(node.body, ctx)

    _stmt_AsyncWith = _stmt_With

    def _stmt_Try(self, node: ast.Try, ctx: _Ctx) -> None:
        self._stmts(node.body, ctx)
        for handler in node.handlers:
            if handler.type is not None:
                self._expr(handler.type, ctx)
            if handler.name:
                self._bind(handler.name, None, ctx)
            self._stmts(handler.body, ctx)
        self._stmts(node.orelse, ctx)
        self._stmts(node.finalbody, ctx)

    _stmt_TryStar = _stmt_Try

    def _stmt_Match(self, node: ast.Match, ctx: _Ctx) -> None:
        self._expr(node.subject, ctx)
        for case in node.cases:
            self._expr(case.pattern, ctx)
            for name in _pattern_names(case.pattern):
                self._bind(name, None, ctx)
            if case.guard is not None:
                self._expr(case.guard, ctx)
            self._stmts(case.body, ctx)

    def _stmt_Delete(self, node: ast.Delete, ctx: _Ctx) -> None:
        for target in node.targets:
            if isinstance(target, ast.Name):
                if not ctx.scopes:
                    self.module.pop(target.id, None)
            else:
                self._expr(target, ctx)

    def _stmt_Global(self, node: ast.Global, ctx: _Ctx) -> None:
        """Handled when the enclosing scope is built."""

    _stmt_Nonlocal = _stmt_Global

    # -- expressions -----------------------------------------------------------------

    def _expr(self, node: ast.AST, ctx: _Ctx) -> None:
        """Walk an expression without recursion (expressions can be very deep)."""
        stack: list[tuple[ast.AST, tuple[_Scope, ...]]] = [(node, ctx.scopes)]
        while stack:
            item, scopes = stack.pop()
            if isinstance(item, (ast.Name, ast.Attribute)):
                base = self._chain(item, scopes, ctx)
                if base is not None:
                    stack.append((base, scopes))
            elif isinstance(item, ast.Lambda):
                args = item.args
                stack.extend((d, scopes) for d in [*args.defaults, *filter(None, args.kw_defaults)])
                inner = _Scope(bindings=dict.fromkeys(_parameters(args)))
                stack.append((item.body, (*scopes, inner)))
            elif isinstance(item, _COMPREHENSIONS):
                names = {n.id for g in item.generators for n in ast.walk(g.target)
                         if isinstance(n, ast.Name)}
                inner = _Scope(bindings=dict.fromkeys(names), kind="comprehension")
                stack.extend((child, (*scopes, inner)) for child in _children(item))
            elif isinstance(item, ast.NamedExpr):
                self._walrus(item.target.id, scopes, ctx)
                stack.append((item.value, scopes))
            else:
                if isinstance(item, ast.Call):
                    self._call(item, scopes, _Ctx(ctx.where, scopes, ctx.owner, ctx.sink))
                stack.extend((child, scopes) for child in _children(item))

    def _chain(self, node: ast.Name | ast.Attribute, scopes: tuple[_Scope, ...],
               ctx: _Ctx) -> ast.expr | None:
        """Check a maximal ``a.b.c`` chain; return its base when that is not a name."""
        attrs: list[str] = []
        base: ast.expr = node
        while isinstance(base, ast.Attribute):
            attrs.append(base.attr)
            base = base.value
        if isinstance(base, ast.Name):
            if base is node and not isinstance(node.ctx, ast.Load):
                return None
            qual = self._lookup(base.id, scopes, ctx.sink)
            rest = None
        else:
            qual = self._qualify(base, scopes)
            rest = base
        if qual is not None:
            self._check(".".join([qual, *reversed(attrs)]), node, ctx)
        for attr in attrs:
            if attr in _DIGGING_ATTRS:
                self._dynamic(attr, node, ctx)
        return rest

    def _walrus(self, name: str, scopes: tuple[_Scope, ...], ctx: _Ctx) -> None:
        for scope in reversed(scopes):
            if scope.kind != "comprehension":
                scope.bindings[name] = None
                return
        self.module[name] = _Def(None, ctx.sink)

    def _call(self, node: ast.Call, scopes: tuple[_Scope, ...], ctx: _Ctx) -> None:
        """Calls that import, run code, or look attributes up by name."""
        func = self._qualify(node.func, scopes)
        if func is None:
            return
        first = _literal_str(node.args[0]) if node.args else None
        if func in _EXEC_FUNCS:
            self._dynamic(func.removeprefix("builtins."), node, ctx)
        elif func in _IMPORT_FUNCS:
            if first and not first.startswith("."):
                self._check(first, node, ctx)
            else:
                self._dynamic(func.removeprefix("builtins."), node, ctx)
        elif func == "builtins.getattr" and len(node.args) >= 2:
            if _literal_str(node.args[1]) in _DIGGING_ATTRS:
                self._dynamic(str(_literal_str(node.args[1])), node, ctx)
            qual = self._call_qual(node, scopes)
            if qual is not None:
                self._check(qual, node, ctx)
            elif (_literal_str(node.args[1]) is None
                  and self._qualify(node.args[0], scopes) is not None):
                self._dynamic("getattr", node, ctx)
        elif func.startswith("get_ipython()."):
            self._ipython(func.removeprefix("get_ipython()."), node, ctx)

    # -- IPython ---------------------------------------------------------------------

    def _ipython(self, method: str, node: ast.Call, ctx: _Ctx) -> None:
        code, unverifiable = ipython_call(method, [_literal_str(a) for a in node.args])
        if unverifiable is not None:
            self._dynamic(unverifiable, node, ctx)
        here = ctx.where.line(node)
        for part in code:
            where = (replace(ctx.where, fixed=here) if part.fixed else
                     replace(ctx.where, base=here, fixed=None))
            self._run_code(part.source, replace(ctx, where=where), label=part.label)

    # -- the report ------------------------------------------------------------------

    def report(self) -> ScanFindings:
        for node, ctx in self.deferred:
            self._guarded(self._body, node, ctx)
        tainted = _closure(self.module, lambda d: d.sink.direct or bool(
            d.qual and _matches(d.qual, self.forbid)))
        unverified = _closure(self.module, lambda d: d.sink.dynamic)
        return ScanFindings(uses=_sorted_unique(self.uses), tainted=tainted,
                          dynamic=_sorted_unique(self.dynamic), errors=tuple(self.errors),
                          unverified=unverified)


# -- helpers -----------------------------------------------------------------------

def _closure(module: dict[str, _Def], seed: Callable[[_Def], bool]) -> frozenset[str]:
    """Names whose definition satisfies ``seed`` or references such a name."""
    # A search over reversed edges: linear in the names and references, where a
    # repeat-until-stable sweep is quadratic on a long chain of one-line functions.
    users: dict[str, list[str]] = {}
    for name, definition in module.items():
        for ref in definition.sink.refs:
            users.setdefault(ref, []).append(name)
    marked = {name for name, d in module.items() if seed(d)}
    stack = list(marked)
    while stack:
        for user in users.get(stack.pop(), ()):
            if user not in marked:
                marked.add(user)
                stack.append(user)
    return frozenset(marked)


def _sorted_unique(uses: list[Use]) -> tuple[Use, ...]:
    seen: dict[tuple[int, int, str, str], Use] = {}
    for use in uses:
        seen.setdefault((use.cell, use.line, use.name, use.function or ""), use)
    return tuple(seen[key] for key in sorted(seen))


def _literal_str(node: ast.AST | None) -> str | None:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    return None


def _has_fromlist(call: ast.Call) -> bool:
    """``__import__(name, g, l, fromlist)`` with a non-empty ``fromlist``."""
    values = [call.args[3]] if len(call.args) >= 4 else []
    values += [k.value for k in call.keywords if k.arg == "fromlist"]
    return any(not (isinstance(v, (ast.List, ast.Tuple)) and not v.elts)
               and not (isinstance(v, ast.Constant) and not v.value) for v in values)


def _parameters(args: ast.arguments) -> set[str]:
    names = {a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)}
    names |= {a.arg for a in (args.vararg, args.kwarg) if a is not None}
    return names


def _local_names(body: list[ast.stmt]) -> tuple[set[str], set[str], set[str]]:
    """``(bound, global, nonlocal)`` names of a scope's own statements."""
    bound: set[str] = set()
    declared_global: set[str] = set()
    declared_nonlocal: set[str] = set()
    stack: list[ast.AST] = list(body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Global):
            declared_global.update(node.names)
        elif isinstance(node, ast.Nonlocal):
            declared_nonlocal.update(node.names)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
            continue
        elif isinstance(node, _NESTED_SCOPES):
            continue
        elif isinstance(node, ast.Name) and not isinstance(node.ctx, ast.Load):
            bound.add(node.id)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound.update((a.asname or a.name).split(".")[0] for a in node.names if a.name != "*")
        elif isinstance(node, ast.ExceptHandler) and node.name:
            bound.add(node.name)
        elif isinstance(node, ast.pattern):
            bound.update(_pattern_names(node))
        stack.extend(_children(node))
    return bound, declared_global, declared_nonlocal


def _children(node: ast.AST) -> list[ast.AST]:
    """``list(ast.iter_child_nodes(node))`` in the same order, without two generators, and
    without the ``ctx`` marker (``Load``, ``Store``) of a name, which holds no name."""
    found: list[ast.AST] = []
    for name in node._fields:
        if name == "ctx":
            continue
        value = getattr(node, name, None)
        if isinstance(value, ast.AST):
            found.append(value)
        elif isinstance(value, list):
            found.extend(item for item in value if isinstance(item, ast.AST))
    return found


def _pattern_names(pattern: ast.AST) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(pattern):
        if isinstance(node, (ast.MatchAs, ast.MatchStar)) and node.name:
            names.add(node.name)
        elif isinstance(node, ast.MatchMapping) and node.rest:
            names.add(node.rest)
    return names
