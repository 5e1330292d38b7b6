"""Generate mutants of an instructor notebook's model solution (for ``validate --mutants``).

A mutant is the instructor notebook with one small fault put into one function
defined in a solution region (``### BEGIN SOLUTION`` ... ``### END SOLUTION``).
Generation is deterministic: the same notebook always gives the same mutants,
with the same ids, in the same order.

Operators come from mutmut 3 (``mutmut.mutation.mutators``, built on libcst):
arithmetic and comparison swaps, ``and``/``or``, ``is``/``in`` negation,
``break``/``continue``, constants + 1, ``True``/``False``, dropped unary
operators, ``x += y`` written as ``x = y``, a forced ternary. mutmut has no
operator for the faults numerical-methods students make, so these are written
here (:class:`_NumericalMutations`): dropped and duplicated terms, off-by-one in
``range`` ends, indices and slice bounds, a float32 cast of a returned value, a
reversed loop and a returned sequence in the other (often still valid) order.

Two choices keep the mutants to faults a check should see: the functions mutated
are the ones the checks call and the solution functions these call in turn
(:func:`graded_functions`: a fault in a helper is a fault in the graded result);
and the values of matplotlib's style keywords (``figsize``, ``lw``, ``alpha``,
... in :data:`STYLE_KEYWORDS`) are left alone: a thicker line is a different
figure, not a mistake.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator

import libcst as cst
import nbformat
from libcst.metadata import MetadataWrapper, PositionProvider
from mutmut.mutation import mutators as mutmut_ops

__all__ = ["Mutant", "generate_mutants", "graded_functions", "solution_functions",
           "reference_copies", "REF_PREFIX", "STYLE_KEYWORDS"]

#: the prefix of the reference's functions copied into a probe notebook
REF_PREFIX = "_ngref_"

#: keyword arguments of matplotlib calls that only set how a figure looks: not mutated
STYLE_KEYWORDS = frozenset({
    "figsize", "dpi", "lw", "linewidth", "linewidths", "ls", "linestyle", "ms", "markersize",
    "mew", "markeredgewidth", "alpha", "fontsize", "zorder", "pad", "shrink", "aspect",
})

#: mutmut's operators that make sense for numerical code (its string, argument and
#: ``x = None`` operators only give mutants every check kills by a crash)
_MUTMUT: tuple[tuple[type, Callable[..., Iterable[cst.CSTNode]], str], ...] = (
    (cst.BaseNumber, mutmut_ops.operator_number, "constant"),
    (cst.Name, mutmut_ops.operator_name, "boolean"),
    (cst.AugAssign, mutmut_ops.operator_augmented_assignment, "drop-accumulation"),
    (cst.UnaryOperation, mutmut_ops.operator_remove_unary_ops, "drop-unary"),
    (cst.CSTNode, mutmut_ops.operator_keywords, "keyword"),
    (cst.CSTNode, mutmut_ops.operator_swap_op, "operator"),
    (cst.IfExp, mutmut_ops.operator_if_exp, "ternary"),
)


@dataclass(frozen=True)
class Mutant:
    """One mutant: which function, what changed, and the whole mutated notebook."""

    id: str
    function: str
    operator: str
    line: int  # in the function's cell
    diff: str
    cell: int  # index of the notebook cell that holds the function
    cell_source: str  # the mutated cell


def _one(expr: str) -> cst.BaseExpression:
    return cst.parse_expression(expr)


def _plus(node: cst.BaseExpression, amount: int) -> cst.BaseExpression:
    op: cst.BaseBinaryOp = cst.Add() if amount > 0 else cst.Subtract()
    return cst.BinaryOperation(left=node, operator=op, right=cst.Integer(str(abs(amount))))


def _numerical(node: cst.CSTNode, numpy: str | None) -> Iterator[tuple[cst.CSTNode, str]]:
    """The operators mutmut does not have (see the module docstring)."""
    if isinstance(node, cst.BinaryOperation) and isinstance(node.operator, (cst.Add, cst.Subtract)):
        yield node.left.with_changes(lpar=node.lpar, rpar=node.rpar) \
            if isinstance(node.left, cst.BinaryOperation) else node.left, "drop-term"
        dup = cst.BinaryOperation(left=node, operator=node.operator, right=node.right)
        yield dup, "duplicate-term"
    elif isinstance(node, cst.Call) and isinstance(node.func, cst.Name) \
            and node.func.value == "range" and 1 <= len(node.args) <= 3:
        stop = 0 if len(node.args) == 1 else 1
        for amount in (-1, 1):
            args = list(node.args)
            args[stop] = args[stop].with_changes(value=_plus(args[stop].value, amount))
            yield node.with_changes(args=args), "end-condition"
    elif isinstance(node, cst.SubscriptElement) and isinstance(node.slice, cst.Index) \
            and isinstance(node.slice.value, cst.Name):
        yield node.with_changes(slice=cst.Index(_plus(node.slice.value, 1))), "off-by-one"
    elif isinstance(node, cst.Slice):
        if node.upper is not None and not isinstance(node.upper, cst.UnaryOperation):
            yield node.with_changes(upper=_plus(node.upper, -1)), "boundary"
        if node.lower is not None:
            yield node.with_changes(lower=_plus(node.lower, 1)), "boundary"
    elif isinstance(node, cst.For) and not node.asynchronous:
        iterable = cst.Call(func=cst.Name("reversed"),
                            args=[cst.Arg(cst.Call(func=cst.Name("list"), args=[cst.Arg(node.iter)]))])
        yield node.with_changes(iter=iterable), "reversed-loop"
    elif isinstance(node, cst.Return) and node.value is not None \
            and not isinstance(node.value, (cst.Tuple, cst.Lambda, cst.Name)) and numpy:
        cast = _one(f"{numpy}.asarray(None, dtype={numpy}.float32)")
        assert isinstance(cast, cst.Call)
        args = [cast.args[0].with_changes(value=node.value), cast.args[1]]
        yield node.with_changes(value=cast.with_changes(args=args)), "float32"
    if isinstance(node, cst.Return) and isinstance(node.value, cst.Name):
        yield node.with_changes(value=_one(f"{node.value.value}[::-1]")), "ordering"


def _docstring(function: cst.FunctionDef) -> cst.CSTNode | None:
    body = function.body.body
    if body and isinstance(body[0], cst.SimpleStatementLine) and body[0].body \
            and isinstance(body[0].body[0], cst.Expr) \
            and isinstance(body[0].body[0].value, (cst.SimpleString, cst.ConcatenatedString)):
        return body[0]
    return None


class _Collect(cst.CSTVisitor):
    """Every node of ``function`` (its docstring, decorators and the values of style
    keywords left out), in source order."""

    def __init__(self, skip: cst.CSTNode | None) -> None:
        self.nodes: list[cst.CSTNode] = []
        self._skip = skip

    def on_visit(self, node: cst.CSTNode) -> bool:
        if node is self._skip or isinstance(node, cst.Decorator) or (
                isinstance(node, cst.Arg) and node.keyword is not None
                and node.keyword.value in STYLE_KEYWORDS):
            return False
        self.nodes.append(node)
        return True


def _variants(function: cst.FunctionDef, numpy: str | None) -> Iterator[tuple[cst.CSTNode, cst.CSTNode, str]]:
    collect = _Collect(_docstring(function))
    function.body.visit(collect)
    for node in collect.nodes:
        for kind, operator, name in _MUTMUT:
            if isinstance(node, kind):
                for new in operator(node):
                    yield node, new, name
        for new, name in _numerical(node, numpy):
            yield node, new, name


def _solution_lines(source: str) -> set[int]:
    lines, inside = set(), False
    for number, raw in enumerate(source.splitlines(), start=1):
        if "BEGIN SOLUTION" in raw:
            inside = True
        elif "END SOLUTION" in raw:
            inside = False
        elif inside:
            lines.add(number)
    return lines


def solution_functions(notebook: nbformat.NotebookNode) -> list[tuple[int, cst.Module, cst.FunctionDef]]:
    """``(cell index, parsed cell, function)`` for each top-level function written in a
    solution region of a code cell (cells libcst cannot parse, e.g. magics, are skipped)."""
    found = []
    for index, cell in enumerate(notebook.cells):
        source = cell.get("source", "")
        if cell.get("cell_type") != "code" or "BEGIN SOLUTION" not in source:
            continue
        try:
            wrapper = MetadataWrapper(cst.parse_module(source), unsafe_skip_copy=True)
        except cst.ParserSyntaxError:
            continue
        positions = wrapper.resolve(PositionProvider)
        inside = _solution_lines(source)
        for statement in wrapper.module.body:
            if isinstance(statement, cst.FunctionDef):
                where = positions[statement]
                if inside & set(range(where.start.line, where.end.line + 1)):
                    found.append((index, wrapper.module, statement))
    return found


def graded_functions(notebook: nbformat.NotebookNode, called: set[str]) -> set[str]:
    """``called`` (the solution functions the checks call) and every solution function
    these call, directly or through others."""
    bodies = {f.name.value: f for _, _, f in solution_functions(notebook)}
    graded, todo = set(), [n for n in called if n in bodies]
    while todo:
        name = todo.pop()
        if name in graded:
            continue
        graded.add(name)
        used = _Names()
        bodies[name].body.visit(used)
        todo += [n for n in used.names if n in bodies and n not in graded]
    return graded


class _Names(cst.CSTVisitor):
    def __init__(self) -> None:
        self.names: set[str] = set()

    def visit_Name(self, node: cst.Name) -> None:
        self.names.add(node.value)


def _numpy_alias(notebook: nbformat.NotebookNode) -> str | None:
    for cell in notebook.cells:
        for line in cell.get("source", "").splitlines():
            if line.strip() in ("import numpy as np", "import numpy"):
                return line.split()[-1]
    return None


def generate_mutants(notebook: nbformat.NotebookNode) -> list[Mutant]:
    """Every mutant of the notebook's solution functions, in source order."""
    numpy = _numpy_alias(notebook)
    mutants: list[Mutant] = []
    for cell_index, module, function in solution_functions(notebook):
        name = function.name.value
        before = module.code_for_node(function)
        seen: set[str] = set()
        for count, (old, new, operator) in enumerate(_variants(function, numpy)):
            mutated = function.deep_replace(old, new)
            assert isinstance(mutated, cst.FunctionDef)
            after = module.code_for_node(mutated)
            if after == before or after in seen:
                continue
            seen.add(after)
            diff = "".join(difflib.unified_diff(before.splitlines(True), after.splitlines(True),
                                                f"{name} (model solution)", f"{name} (mutant)", n=1))
            line = next((i for i, (a, b) in enumerate(zip(before.splitlines(), after.splitlines()), 1)
                         if a != b), 1)
            cell_source = module.deep_replace(function, mutated)
            assert isinstance(cell_source, cst.Module)
            mutants.append(Mutant(f"{name}-{count:03d}-{operator}", name, operator, line, diff,
                                  cell_index, cell_source.code))
    return mutants


class _Rename(cst.CSTTransformer):
    def __init__(self, names: set[str]) -> None:
        self._names = names

    def leave_Name(self, original: cst.Name, updated: cst.Name) -> cst.Name:
        if updated.value in self._names:
            return updated.with_changes(value=REF_PREFIX + updated.value)
        return updated


def reference_copies(notebook: nbformat.NotebookNode) -> str:
    """The solution functions as written, renamed ``_ngref_<name>`` (calls between them
    too), for a probe notebook that compares a mutant with the reference."""
    functions = solution_functions(notebook)
    names = {f.name.value for _, _, f in functions}
    parts = []
    for _, module, function in functions:
        renamed = function.visit(_Rename(names))
        parts.append(module.code_for_node(renamed))
    return "\n\n".join(parts)
