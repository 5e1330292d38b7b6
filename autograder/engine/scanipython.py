"""IPython syntax for the static scan: cells turned into Python, and the code a magic runs.

A notebook cell may hold ``%magics``, ``!commands`` and ``obj?``; the scan
(:mod:`autograder.engine.staticscan`) parses each cell through IPython's own
``TransformerManager`` (:class:`CellParser`), so what it walks is what IPython
would run. IPython turns a magic into a call such as
``get_ipython().run_line_magic("timeit", "-n 3 hull(p)")``; :func:`ipython_call`
says what such a call runs:

* **magics that run Python** (``%time``, ``%timeit``, ``%prun``, ``%debug``,
  ``%%time``, ``%%timeit``, ``%%capture``, ``%%prun``, ``%%debug``) give their
  code, to be scanned as if written in the cell;
* **magics and methods that cannot be verified** (``%run``, ``%load_ext``,
  ``%%writefile``, ``get_ipython().ex(...)``, a magic whose name or code is
  computed) give the name the scan reports as dynamic;
* everything else (``%matplotlib``, ``!ls``, ...) runs no Python of the student's.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["CellParser", "MagicCode", "ipython_call"]

#: ``get_ipython()`` methods that run no Python code of the student's (or whose code
#: is handled as a magic)
_IPYTHON_SAFE = frozenset({"run_line_magic", "run_cell_magic", "system", "getoutput",
                           "set_next_input", "showtraceback"})
_CODE_MAGICS = frozenset({"time", "timeit", "prun", "debug", "capture"})
_UNVERIFIABLE_LINE_MAGICS = frozenset({"run", "load_ext", "reload_ext", "aimport"})
_UNVERIFIABLE_CELL_MAGICS = frozenset({"writefile", "file"})
_MAGIC_OPTIONS_WITH_VALUE = frozenset({"-n", "-r", "-p", "-l", "-s", "-T", "-D"})


class CellParser:
    """Parses cells in IPython syntax with IPython's own ``TransformerManager``.

    IPython is imported on the first cell that may need it (about 0.25 s of the
    grader's CPU, on the path to a batch's first result); a notebook of plain
    Python never imports it here (see :func:`_untransformed`).
    """

    def __init__(self) -> None:
        self._transformer: Any = None

    @property
    def transformer(self) -> Any:
        if self._transformer is None:
            from IPython.core.inputtransformer2 import TransformerManager

            self._transformer = TransformerManager()
        return self._transformer

    def parse(self, source: str) -> ast.Module:
        """The Python tree of a cell; raises what ``ast.parse`` or IPython's transformer raise."""
        return (_untransformed(source) or self._parse_python(source)
                or ast.parse(self.transformer.transform_cell(source)))

    def _parse_python(self, source: str) -> ast.Module | None:
        """The tree of a cell that is Python once IPython's line passes ran; else None.

        ``transform_cell`` runs line passes (blank first lines, common indentation,
        pasted prompts, a ``%%`` cell magic), then token passes that tokenize the
        whole cell for each special line (``%magic``, ``!cmd``, ``a = %magic``,
        ``obj?``), most of a scan's cost. Every token pass looks for a token that
        cannot stand there in Python, so code that parses after the line passes
        is what ``transform_cell`` would return: it is parsed without them. Any
        other cell (or any failure here) takes the whole ``transform_cell``, so
        its tree, or its error, is exactly as before.
        """
        cell = source if source.endswith("\n") else source + "\n"
        lines = cell.splitlines(keepends=True)
        try:
            for transform in self.transformer.cleanup_transforms + self.transformer.line_transforms:
                lines = transform(lines)
            return ast.parse("".join(lines))
        except Exception:  # noqa: BLE001 - the whole transform decides, and reports
            return None


def _untransformed(source: str) -> ast.Module | None:
    """The tree of a cell that IPython's line passes cannot change and that parses; else None.

    The line passes act only on a cell whose first line is blank or indented
    (``leading_empty_lines``, ``leading_indent``), whose first line starts with
    ``%%`` (``cell_magic``), or with a line starting with a pasted prompt (``>>>``,
    ``...``, ``In [n]:``, ``...:``, a vi mode's ``[nav]``); the test here is wider than
    theirs (any line starting with one of these or ``%``, after its indentation), so
    every cell they could change goes to IPython. Of the rest, a cell that parses
    as Python is what ``transform_cell`` returns (the token passes leave Python
    unchanged: see :meth:`CellParser._parse_python`), so its tree is the same;
    written by hand because IPython offers no test short of importing it.
    """
    lines = source.splitlines()  # as IPython splits the cell
    if not lines or not lines[0].strip() or lines[0][0] in " \t\f":
        return None
    for line in lines:
        if line.lstrip().startswith(("%", ">>>", "...", "In [", "[nav]", "[ins]")):
            return None
    try:
        return ast.parse(source)
    except Exception:  # noqa: BLE001 - IPython's passes, then the full transform, decide
        return None


@dataclass(frozen=True)
class MagicCode:
    """Python code a magic runs, to be scanned as if written in the cell.

    Attributes
    ----------
    source : str
        The code, without the magic's options.
    label : str
        Added to a parse error's message: ``" (in %timeit)"``.
    fixed : bool
        True for a line magic's code: all of it is reported at the call's line.
        False for a cell magic's body: its lines count on from the call's line.
    """

    source: str
    label: str
    fixed: bool


def ipython_call(method: str, args: Sequence[str | None]
                 ) -> tuple[tuple[MagicCode, ...], str | None]:
    """What ``get_ipython().method(*args)`` runs: the code to scan, and what cannot be verified.

    ``args`` are the call's arguments where they are string literals, else None.
    Returns the code the call runs, in order, and the name to report as a
    dynamic use (or None).
    """
    if method == "run_line_magic":
        return _line_magic([*args, None, None])
    if method == "run_cell_magic":
        return _cell_magic([*args, None, None, None])
    if method not in _IPYTHON_SAFE:
        return (), f"get_ipython().{method}"
    return (), None


def _line_magic(args: Sequence[str | None]) -> tuple[tuple[MagicCode, ...], str | None]:
    name, arg = args[0], args[1]
    if name is None or arg is None:
        return (), "%<computed magic>"
    if name in _CODE_MAGICS:
        return (MagicCode(_strip_magic_options(arg), f" (in %{name})", fixed=True),), None
    if name in _UNVERIFIABLE_LINE_MAGICS:
        return (), f"%{name}"
    return (), None


def _cell_magic(args: Sequence[str | None]) -> tuple[tuple[MagicCode, ...], str | None]:
    name, line, body = args[:3]
    if name is None or body is None:
        return (), "%%<computed magic>"
    if name in _CODE_MAGICS:
        code = []
        if name == "timeit" and line:
            code.append(MagicCode(_strip_magic_options(line), " (in %%timeit)", fixed=True))
        code.append(MagicCode(body, f" (in %%{name})", fixed=False))
        return tuple(code), None
    if name in _UNVERIFIABLE_CELL_MAGICS:
        return (), f"%%{name}"
    return (), None


def _strip_magic_options(arg: str) -> str:
    """The code of a ``%timeit -n 10 -r 3 code`` style argument."""
    words = arg.split(" ")
    while words and words[0].startswith("-"):
        option = words.pop(0)
        if option in _MAGIC_OPTIONS_WITH_VALUE and words:
            words.pop(0)
        while words and words[0] == "":
            words.pop(0)
    return " ".join(words)
