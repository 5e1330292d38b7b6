"""Everything a check author needs, in one import: ``from autograder.checks import ...``.

An assignment's checks are ordinary pytest functions over the fixtures of
:mod:`autograder.engine.plugin`. This module gives them:

* the fixtures' types, for annotations: :class:`Student` (``student``),
  :class:`Credit` (``credit``), :class:`Feedback` (``feedback``),
  :class:`VariantView` (``variant``: the student's parameters);
* :class:`CheckFailure` and the staged comparisons of :mod:`autograder.checks.compare_arrays`
  (:func:`expect_array`, :func:`expect_close`, :func:`expect_equal`,
  :func:`expect_indices`, :func:`expect_int`, :func:`expect_number`,
  :func:`describe`, :func:`same_cycle`, :func:`is_rotation_reversed`), right on
  NaN and infinities;
* named datasets: :class:`Dataset` holds how to build the data, the points it
  is worth, its tolerance and the reason for that tolerance, and a hint;
  :func:`over_datasets` parametrises a check over a mapping of them (or some
  of them), each item carrying its points and named by its key;
* partial credit for a right answer that breaks a convention (clockwise,
  1-based, transposed, ...): one :class:`Conventions` table per assignment says
  what each broken convention keeps of the points; :meth:`Conventions.record`
  collects what one check found (a :class:`Broken`) and ends the check;
* calling the student: ``student.map(name, [args, ...])`` makes many calls of one
  function in one batch (an iterator of their values, each call's error raised at its
  position); :func:`explain_errors` turns an exception of a known
  type (``OverflowError``, ...) into a failure that says how to avoid it;
  :func:`call_for_figure` calls a plotting function and finds its figure;
* text for messages: :func:`show_number` (every digit that matters, so
  ``0.9999999`` never reads as ``1``), :func:`show_point`, :func:`show_list`,
  :func:`show_points`, :func:`plural`, :func:`sentence`, :func:`sentences`;
* pictures: :func:`is_figure` and :func:`expect_figure` (figure data from the
  boundary),
  :func:`curve_pieces` and :func:`curve_points` (what a figure draws, piece by
  piece or as one point set),
  :func:`figure_png` (the PNG inside figure data), :func:`render_png` (a
  figure drawn by the check) and :func:`side_by_side` (the student's picture
  beside a reference drawing).

Assertion rewriting is off while checks run, so a check fails with its message
only: raise :class:`CheckFailure` (or ``assert cond, "message"``) with text a
student can act on, computed from data, never from the check's source.

Example
-------
::

    from autograder.checks import Credit, Dataset, Student, expect_close, over_datasets

    DATASETS = {
        "small": Dataset(lambda rng: np.linspace(0, 1, 5), points=1, tolerance=1e-12,
                         reason="five nodes: rounding only"),
        "unseen": Dataset(lambda rng: rng.uniform(0, 1, 40), points=2, tolerance=1e-10,
                          reason="40 random nodes, well conditioned"),
    }

    @over_datasets(DATASETS)
    def test_mean(student: Student, rng, name: str) -> None:
        data = DATASETS[name]
        x = data.build(rng)
        expect_close(student.mean(x), x.mean(), rtol=data.tolerance, atol=0, name="mean(x)")
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Generic, TypeGuard, TypeVar

import numpy as np
import pytest

from autograder.checks.compare_arrays import (
    describe,
    expect_array,
    expect_close,
    expect_equal,
    expect_indices,
    expect_int,
    expect_number,
    is_rotation_reversed,
    same_cycle,
)
from autograder.checks.compare_curves import (
    curve_pieces,
    curve_points,
    decode_png,
    render_side_by_side,
)
from autograder.engine.plugin import Credit, Feedback, VariantView
from autograder.engine.proxy import Student
from autograder.errors import CheckFailure, StudentException

__all__ = [
    "Broken",
    "CheckFailure",
    "Conventions",
    "Credit",
    "Dataset",
    "Feedback",
    "FigureData",
    "Student",
    "VariantView",
    "call_for_figure",
    "curve_pieces",
    "curve_points",
    "decode_png",
    "describe",
    "expect_array",
    "expect_close",
    "expect_equal",
    "expect_figure",
    "expect_indices",
    "expect_int",
    "expect_number",
    "explain_errors",
    "figure_png",
    "is_figure",
    "is_rotation_reversed",
    "over_datasets",
    "plural",
    "render_png",
    "same_cycle",
    "sentence",
    "sentences",
    "show_list",
    "show_number",
    "show_point",
    "show_points",
    "side_by_side",
]

T = TypeVar("T")

#: Figure data as it comes back from the student's process: a dict with the
#: figure's ``axes`` (each with its ``lines``, ``collections``, ...) and its ``png``.
FigureData = Mapping[str, Any]


# ---------------------------------------------------------------------------
# named datasets
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Dataset(Generic[T]):
    """A named input of a check: how to build it, what it is worth, how exact it must be.

    Attributes
    ----------
    build : callable
        ``build(rng) -> data``; ``rng`` is the check's ``rng`` fixture (seeded
        from the assignment and the student), used only by unseen datasets.
    points : float
        Points of the check item that uses this dataset (default 1).
    tolerance : float or None
        The tolerance the comparison uses (relative or absolute: the check
        says which), or None when the answer is compared exactly.
    reason : str
        Why this tolerance: what a correct method achieves here and what a
        wrong one misses by. Required whenever ``tolerance`` is set.
    hint : str
        Extra advice for a student who fails this dataset (shown only with a
        failure that this dataset can cause).
    """

    build: Callable[[np.random.Generator], T]
    points: float = 1
    tolerance: float | None = None
    reason: str = ""
    hint: str = ""

    @property
    def tol(self) -> float:
        """``tolerance`` for a check that compares with one: a TypeError if it is None."""
        if self.tolerance is None:
            raise TypeError("This dataset has no `tolerance`, but its check compares with one: "
                            "give it a tolerance and the reason for it.")
        return float(self.tolerance)

    def __post_init__(self) -> None:
        if not callable(self.build):
            raise TypeError(f"`build` must be a function of the rng; got {self.build!r}.")
        if isinstance(self.points, bool) or not isinstance(self.points, (int, float)) \
                or not math.isfinite(self.points) or self.points < 0:
            raise ValueError(f"`points` must be a finite number >= 0; got {self.points!r}.")
        if self.tolerance is not None:
            if not isinstance(self.tolerance, (int, float)) or not self.tolerance >= 0:
                raise ValueError(f"`tolerance` must be a number >= 0 or None; "
                                 f"got {self.tolerance!r}.")
            if not self.reason.strip():
                raise ValueError("A dataset with a `tolerance` needs a `reason`: say what a "
                                 "correct method achieves there and what a wrong one misses by.")


def over_datasets(datasets: Mapping[str, Any], argname: str = "name", *,
                  points: float | Callable[[Any], float] | None = None,
                  only: Iterable[str] | None = None) -> pytest.MarkDecorator:
    """Parametrise a check over ``datasets``, each item named by its key and worth its points.

    Parameters
    ----------
    datasets : mapping of str to Dataset (or any object with a ``points`` attribute)
        The check receives each key in turn as ``argname``.
    argname : str, optional
        The check's argument that receives the key (default ``"name"``).
    points : float or callable, optional
        Override the points of every item (a number), or compute them from
        the dataset (a function); default: each dataset's ``points``
        attribute, or 1 for a value without one.
    only : iterable of str, optional
        Run the check over these keys only, in this order (a check that
        needs some of an assignment's datasets); each must be a key of
        ``datasets``.

    Returns
    -------
    pytest.MarkDecorator
        ``pytest.mark.parametrize(argname, [pytest.param(key,
        marks=pytest.mark.points(w), id=key), ...])``.
    """
    if not datasets:
        raise ValueError("`datasets` must name at least one dataset.")
    keys = list(datasets) if only is None else list(only)
    unknown = [key for key in keys if key not in datasets]
    if unknown or not keys:
        raise ValueError(f"`only` must name datasets among {show_list(datasets, limit=20)}; "
                         f"got {show_list(keys, limit=20)}.")

    def weight(value: Any) -> float:
        if points is None:
            return float(getattr(value, "points", 1))
        return float(points(value) if callable(points) else points)

    params = [pytest.param(key, marks=pytest.mark.points(weight(datasets[key])), id=key)
              for key in keys]
    return pytest.mark.parametrize(argname, params)


# ---------------------------------------------------------------------------
# partial credit for broken conventions
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Conventions:
    """What a right answer keeps of a check's points when it breaks a convention.

    One table per assignment, written once beside its checks. A check collects
    what it finds with :meth:`record` and ends with :meth:`Broken.finish`;
    several broken conventions multiply their fractions.

    Attributes
    ----------
    fractions : mapping of str to float
        Convention (``"clockwise"``, ``"one-based"``, ...) -> the share of the
        points a right answer keeps when it breaks it, in (0, 1).

    Example
    -------
    ::

        CONVENTIONS = Conventions({"clockwise": 0.5, "closed": 0.75})

        broken = CONVENTIONS.record()
        broken.note("clockwise", "your hull is right but clockwise")
        broken.finish(credit)  # credit.partial(0.5, "Your hull is right but clockwise.")
    """

    fractions: Mapping[str, float]

    def __post_init__(self) -> None:
        for key, value in self.fractions.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not 0 < value < 1:
                raise ValueError(f"The fraction kept for {key!r} must lie strictly between "
                                 f"0 and 1; got {value!r}.")
        object.__setattr__(self, "fractions", MappingProxyType(dict(self.fractions)))

    def record(self) -> Broken:
        """An empty record of the conventions one check finds broken."""
        return Broken(self)

    def partial(self, credit: Credit, key: str, message: str) -> None:
        """End the check now: one convention broken, ``credit.partial(fraction, message)``."""
        broken = self.record()
        broken.note(key, message)
        broken.finish(credit)


@dataclass
class Broken:
    """The conventions one check found broken: key -> the first message about it."""

    conventions: Conventions
    notes: dict[str, str] = field(default_factory=dict)

    def note(self, key: str, message: str, *, replace: bool = False) -> None:
        """Record ``key`` as broken; the first message stays unless ``replace``."""
        if key not in self.conventions.fractions:
            raise KeyError(f"{key!r} is not a convention of this assignment; known: "
                           f"{', '.join(self.conventions.fractions)}.")
        if replace or key not in self.notes:
            self.notes[key] = message

    def __len__(self) -> int:
        return len(self.notes)

    @property
    def fraction(self) -> float:
        """The share of the points kept: the product of the broken conventions' fractions."""
        return math.prod(self.conventions.fractions[key] for key in self.notes)

    def message(self) -> str:
        """Every note, each as a sentence, in the order they were found."""
        return sentences(self.notes.values())

    def finish(self, credit: Credit) -> None:
        """End the check: nothing (full points) or ``credit.partial(fraction, message)``."""
        if self.notes:
            credit.partial(self.fraction, self.message())


# ---------------------------------------------------------------------------
# calling the student
# ---------------------------------------------------------------------------


@contextmanager
def explain_errors(call: str, hints: Mapping[str, str], *,
                   traceback: bool = False) -> Iterator[None]:
    """Explain the exceptions of known types that the student's code raises inside the block.

    ``hints`` maps an exception type's name (``"OverflowError"``) to advice on
    avoiding it. Such an exception ends the check with ``"{call} raised
    {type}: {message}. {hint}"`` (and the student's traceback if
    ``traceback``); exceptions of other types pass through unchanged (the
    plugin reports them with their traceback)::

        with explain_errors(f"equispaced_weights({n})", {"OverflowError": HINT}):
            w = student.equispaced_weights(n)
    """
    try:
        yield
    except StudentException as exc:
        kind = exc.exc_type or str(exc).split(" raised ", 1)[-1].split(":", 1)[0]
        if kind not in hints:
            raise
        detail = exc.detail or str(exc).split(": ", 1)[-1]
        text = sentence(f"{call} raised {kind}: {detail}".rstrip(" .")) + " " + hints[kind]
        if traceback and exc.traceback:
            text += f"\n\n{exc.traceback}"
        raise CheckFailure(text.strip()) from None


def call_for_figure(student: Student, fn: str, *args: object, feedback: Feedback | None = None,
                    label: str = "your plot") -> tuple[object, FigureData | None]:
    """Call the student's plotting function ``fn(*args)`` and find the figure it drew.

    Returns
    -------
    value : object
        What ``fn`` returned (a figure returns as :data:`FigureData`).
    figure : FigureData or None
        The figure to judge: the returned one, else the last figure the call
        left open (a function that forgot ``return fig``), else None.

    With ``feedback``, the figure's picture is attached under ``label``.
    """
    value, opened = student.call(fn, *args, figures=True)
    figure = value if is_figure(value) else next(
        (f for f in reversed(opened) if is_figure(f)), None)
    png = figure_png(figure)
    if feedback is not None and png:
        feedback.image(label, png)
    return value, figure


# ---------------------------------------------------------------------------
# text for messages
# ---------------------------------------------------------------------------


def show_number(value: Any, digits: int | None = None) -> str:
    """A number for a message, never rounded into a misleading value.

    With ``digits=None`` (the default) the shortest text that reads back as
    exactly the same double (``repr``), integers without ``.0``: ``0.9999999``
    stays ``0.9999999``, ``1e-300`` stays ``1e-300``. With ``digits`` the
    number is shown to that many significant digits, except that a number
    that is not exactly an integer never prints as one (more digits are used
    until it does not). NaN and infinities print as ``nan``, ``inf``, ``-inf``.
    """
    if isinstance(value, (complex, np.complexfloating)) and complex(value).imag != 0:
        z = complex(value)
        return f"({show_number(z.real, digits)}{'+' if z.imag >= 0 else '-'}" \
               f"{show_number(abs(z.imag), digits)}j)"
    x = float(np.real(value))
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x.is_integer() and abs(x) < 2.0**53:
        return str(int(x))
    if digits is None:
        return repr(x)
    for d in range(max(1, digits), 18):
        text = f"{x:.{d}g}"
        if float(text) != round(float(text)) or d >= 17:
            return text
    return repr(x)  # pragma: no cover - the loop always returns


def show_point(point: Any, digits: int | None = None) -> str:
    """A point as ``(x, y, ...)``, each coordinate by :func:`show_number`."""
    return "(" + ", ".join(show_number(c, digits) for c in np.ravel(np.asarray(point))) + ")"


def show_list(items: Iterable[Any], *, limit: int = 6,
              show: Callable[[Any], str] | None = None) -> str:
    """``[a, b, c, ...]`` with at most ``limit`` items shown and the count of the rest."""
    shown = show or (lambda v: show_number(v) if isinstance(v, (int, float, np.number))
                     and not isinstance(v, bool) else repr(v))
    values = list(items)
    head = ", ".join(shown(v) for v in values[:limit])
    rest = len(values) - limit
    return f"[{head}{f', ... ({rest} more)' if rest > 0 else ''}]"


def plural(count: int | float, word: str, words: str | None = None) -> str:
    """``"1 point"``, ``"2 points"``, ``"0.5 points"``."""
    many = words or word + "s"
    return f"{show_number(count)} {word if count == 1 else many}"


def show_points(score: float, max_score: float | None = None) -> str:
    """``"2 points"``, ``"1.5 of 2 points"``."""
    if max_score is None:
        return plural(score, "point")
    return f"{show_number(score)} of {plural(max_score, 'point')}"


def sentence(text: str) -> str:
    """``text`` with a capital first letter (unless it starts with code) and a final period."""
    text = text.strip()
    if not text:
        return text
    first = text.split(" ", 1)[0]
    if not any(c in first for c in "_()[]`=*"):  # a sentence that starts with code keeps its case
        text = text[:1].upper() + text[1:]
    return text if text.endswith((".", "!", "?")) else text + "."


def sentences(parts: Iterable[str]) -> str:
    """Clauses joined as sentences (each by :func:`sentence`), empty ones left out."""
    return " ".join(sentence(part) for part in parts if part.strip())


# ---------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------


def is_figure(value: object) -> TypeGuard[FigureData]:
    """Whether ``value`` is figure data from the boundary (a mapping with a list of axes)."""
    return isinstance(value, Mapping) and isinstance(value.get("axes"), list)


def expect_figure(value: object, *, name: str, hint: str = "") -> FigureData:
    """Return ``value`` as figure data, or fail: ``name`` should return the Figure it drew on."""
    if not is_figure(value):
        raise CheckFailure(sentences([
            f"{name} should return the matplotlib Figure it drew on (fig, ax = plt.subplots(); "
            f"...; return fig); got {describe(value)}", hint]))
    return value


def figure_png(figure: Any) -> bytes | None:
    """The PNG bytes inside figure data (a dict from the boundary), or None if it has none."""
    if not isinstance(figure, Mapping):
        return None
    png = figure.get("png")
    if isinstance(png, np.ndarray) and png.dtype == np.uint8:
        png = png.tobytes()
    if isinstance(png, (bytes, bytearray, memoryview)) and bytes(png[:8]) == b"\x89PNG\r\n\x1a\n":
        return bytes(png)
    return None


def side_by_side(student: Any, draw_reference: Callable[[Any], object], *,
                 title: str = "your drawing (left) and the reference (right)",
                 left_title: str = "your drawing", right_title: str = "reference") -> bytes:
    """A PNG: the student's picture on the left, ``draw_reference(ax)`` on the right.

    Parameters
    ----------
    student : figure data, PNG bytes or None
        What the student's code drew (its figure data, or the PNG itself).
        When there is no readable picture the left panel says so.
    draw_reference : callable
        ``draw_reference(ax)`` draws the reference on a matplotlib ``Axes``
        (course content stays in the assignment's checks).
    title, left_title, right_title : str, optional
        The picture's title and the panels' titles.
    """
    png = figure_png(student) if isinstance(student, Mapping) else student
    return render_side_by_side(png, draw_reference, title=title, left_title=left_title,
                               right_title=right_title)


def render_png(fig: Any, *, dpi: int = 90) -> bytes:
    """The PNG of a matplotlib ``Figure`` a check drew (for ``feedback.image``)."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()
