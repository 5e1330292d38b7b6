"""Run a notebook's code cells with IPython semantics, without a kernel.

A Jupyter kernel costs about a second to start and a ZeroMQ round trip per
message; ``InteractiveShell`` gives the same cell semantics (magics, ``!cmd``,
``display()``, the last expression echoed) in-process, so the warm parent can
create it once and every forked child inherits it ready to use.
"""

from __future__ import annotations

import ast
import io
import os
import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

from IPython.core.inputtransformer2 import TransformerManager
from IPython.core.interactiveshell import InteractiveShell
from traitlets.config import Config


class BoundedText(io.TextIOBase):
    """A text sink that keeps the first ``limit`` characters and counts the rest.

    Student output can be a flood; this keeps memory bounded while the code runs
    and tells the reader how much was cut.
    """

    def __init__(self, limit: int) -> None:
        self._limit = limit
        self._parts: list[str] = []
        self._kept = 0
        self.dropped = 0

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:  # type: ignore[override]
        text = str(text)
        room = self._limit - self._kept
        if room > 0:
            self._parts.append(text[:room])
            self._kept += min(room, len(text))
        self.dropped += max(0, len(text) - max(room, 0))
        return len(text)

    def flush(self) -> None:
        return None

    def take(self) -> str:
        """Return what was kept (and a note on what was cut) and start afresh."""
        out = "".join(self._parts)
        if self.dropped:
            out += f"\n[... {self.dropped} more characters of output were cut ...]\n"
        self._parts, self._kept, self.dropped = [], 0, 0
        return out


class PythonFirst(TransformerManager):
    """IPython's input transformer, without its token passes for a cell that needs none.

    ``transform_cell`` runs line passes (blank first lines, common indentation,
    pasted prompts, a ``%%`` cell magic), then token passes that tokenize the whole
    cell, in pure Python, once per special line: about a tenth of a submission's
    CPU in the worker for a notebook of long cells. Every token pass looks for a
    token that cannot stand there in Python (``%magic``, ``!cmd``, ``a = %magic``,
    ``obj?``, an escape at the start of a logical line), so a cell that parses
    after the line passes comes out of them unchanged: its text is returned as it
    is then. Any other cell (or any failure here) takes the whole pass, so what
    runs, or the error, is exactly as before. The static scan parses cells the
    same way (:class:`autograder.engine.scanipython.CellParser`).
    """

    def transform_cell(self, cell: str) -> str:
        text = cell if cell.endswith("\n") else cell + "\n"
        lines = text.splitlines(keepends=True)
        try:
            for transform in self.cleanup_transforms + self.line_transforms:
                lines = transform(lines)
            ast.parse("".join(lines))
        except Exception:  # noqa: BLE001 - the whole transform decides, and reports
            return super().transform_cell(cell)
        return "".join(lines)


class GradingShell(InteractiveShell):
    """An ``InteractiveShell`` that records tracebacks instead of printing them."""

    last_traceback: str = ""

    def should_run_async(self, raw_cell: str, *, transformed_cell: str | None = None,
                         preprocessing_exc_tuple: Any = None) -> bool:
        # IPython compiles every cell once more to find a top-level ``await``,
        # ``async for`` or ``async with``; a cell without either word has none.
        if transformed_cell is not None and "await" not in transformed_cell \
                and "async" not in transformed_cell:
            return False
        return super().should_run_async(raw_cell, transformed_cell=transformed_cell,
                                        preprocessing_exc_tuple=preprocessing_exc_tuple)

    def _showtraceback(self, etype: Any, evalue: Any, stb: Any) -> None:  # noqa: D401
        text = self.InteractiveTB.stb2text(stb) if isinstance(stb, list) else str(stb)
        self.last_traceback = text[-20_000:]

    def enable_matplotlib(self, gui: str | None = None) -> tuple[str, str]:
        # ``%matplotlib inline`` would switch to the inline backend, which closes
        # every figure after each cell; the grader keeps Agg so figures survive
        # for checks, and the magic becomes a harmless no-op.
        return ("agg", "agg")


def make_shell() -> GradingShell:
    """Create the shell once in the warm parent (no history database, no colours)."""
    config = Config()
    config.HistoryManager.enabled = False
    config.InteractiveShell.colors = "NoColor"
    config.InteractiveShell.autoindent = False
    shell = GradingShell.instance(config=config)
    shell.input_transformer_manager = PythonFirst()
    shell.InteractiveTB.set_mode(mode="Plain")  # a standard traceback, quick to format
    warnings.filterwarnings("ignore", message=".*non-interactive.*cannot be shown")
    warnings.filterwarnings("ignore", message=".*FigureCanvasAgg is non-interactive.*")
    return shell


def warm_up(shell: GradingShell) -> None:
    """Pay first-use costs once, in the warm parent, instead of in every child.

    matplotlib builds fonts, colour maps and the mathtext parser on first use, and
    IPython imports its traceback machinery on the first error: together tens of
    milliseconds that every forked child would otherwise pay again.
    """
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots()
    ax.plot([0.0, 1.0], [0.0, 1.0], "o-", label="$x$")
    ax.imshow(np.zeros((2, 2)), cmap="coolwarm")
    ax.scatter([0.5], [0.5])
    ax.set_title("$p_x = 0.5$")
    ax.legend()
    fig.savefig(io.BytesIO(), format="png", dpi=72)
    plt.close("all")
    try:
        raise ValueError("warm-up")
    except ValueError:
        shell.showtraceback()
    shell.last_traceback = ""


@dataclass
class CellOutcome:
    """What happened when one cell ran (plain data, sent to the grader)."""

    index: int
    ok: bool
    seconds: float
    ename: str = ""
    evalue: str = ""
    traceback: str = ""

    def to_wire(self) -> dict[str, Any]:
        return {
            "index": self.index,
            "ok": self.ok,
            "seconds": round(self.seconds, 6),
            "ename": self.ename,
            "evalue": self.evalue[:2000],
            "traceback": self.traceback,
        }


@dataclass
class Execution:
    """Run cells in order; a failing cell is recorded and the next one runs."""

    shell: GradingShell
    output: BoundedText
    outcomes: list[CellOutcome] = field(default_factory=list)

    def run(self, cells: list[tuple[int, str | None]], before_cell: Callable[[int], None],
            fetch_source: Callable[[int], str] | None = None) -> None:
        """Run ``cells``; a cell without source (a hidden test) gets it from ``fetch_source``
        once it is reached."""
        pid = os.getpid()
        for index, source in cells:
            if os.getpid() != pid:
                # A child a cell forked, unwound back to here (its setsid() refused, say):
                # it must not run the next cells beside its parent, nor report them.
                os._exit(0)
            before_cell(index)
            if source is None:
                if fetch_source is None:
                    raise ValueError(f"cell {index} came without its source")
                source = fetch_source(index)
            self.outcomes.append(self._run_one(index, source))
        if os.getpid() != pid:
            os._exit(0)

    def _run_one(self, index: int, source: str) -> CellOutcome:
        self.shell.last_traceback = ""
        start = time.perf_counter()
        try:
            result = self.shell.run_cell(source, store_history=False)
        except BaseException as exc:  # SystemExit/KeyboardInterrupt escaping IPython
            return CellOutcome(index, False, time.perf_counter() - start,
                               type(exc).__name__, _safe_str(exc), "")
        seconds = time.perf_counter() - start
        error = result.error_before_exec or result.error_in_exec
        if error is None:
            return CellOutcome(index, True, seconds)
        return CellOutcome(index, False, seconds, type(error).__name__,
                           _safe_str(error), self.shell.last_traceback)


def _safe_str(value: object) -> str:
    """``str(value)`` that survives a hostile ``__str__``."""
    try:
        return str(value)[:2000]
    except BaseException:  # the student's __str__ may raise anything
        return "<unprintable>"


def capture_output(limit: int) -> BoundedText:
    """Send ``sys.stdout`` and ``sys.stderr`` to one bounded buffer."""
    sink = BoundedText(limit)
    sys.stdout = sink  # type: ignore[assignment]
    sys.stderr = sink  # type: ignore[assignment]
    return sink
