"""Everything a check author needs, in one import: ``from autograder.checks import ...``.

An assignment's checks are ordinary pytest functions over the fixtures of
:mod:`autograder.plugin`. This module gives them:

* the fixtures' types, for annotations: :class:`Student` (``student``),
  :class:`Credit` (``credit``), :class:`Feedback` (``feedback``);
* :class:`CheckFailure` and the staged comparisons of :mod:`autograder.compare`
  (:func:`expect_array`, :func:`expect_close`, :func:`expect_equal`,
  :func:`expect_int`, :func:`describe`, :func:`same_cycle`,
  :func:`is_rotation_reversed`), right on NaN and infinities;
* named datasets: :class:`Dataset` holds how to build the data, the points it
  is worth, its tolerance and the reason for that tolerance, and a hint;
  :func:`over_datasets` parametrises a check over a mapping of them, each item
  carrying its points and named by its key;
* text for messages: :func:`show_number` (every digit that matters, so
  ``0.9999999`` never reads as ``1``), :func:`show_point`, :func:`show_list`,
  :func:`show_points`, :func:`plural`, :func:`sentence`;
* pictures: :func:`figure_png` (the PNG inside figure data),
  :func:`render_png` (a figure drawn by the check) and :func:`side_by_side`
  (the student's picture beside a reference drawing).

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
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import numpy as np
import pytest

from autograder.compare import (
    describe,
    expect_array,
    expect_close,
    expect_equal,
    expect_int,
    is_rotation_reversed,
    same_cycle,
)
from autograder.curves import decode_png, render_side_by_side
from autograder.errors import CheckFailure
from autograder.plugin import Credit, Feedback
from autograder.proxy import Student

__all__ = [
    "CheckFailure",
    "Credit",
    "Dataset",
    "Feedback",
    "Student",
    "decode_png",
    "describe",
    "expect_array",
    "expect_close",
    "expect_equal",
    "expect_int",
    "figure_png",
    "is_rotation_reversed",
    "over_datasets",
    "plural",
    "render_png",
    "same_cycle",
    "sentence",
    "show_list",
    "show_number",
    "show_point",
    "show_points",
    "side_by_side",
]

T = TypeVar("T")


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
                  points: float | Callable[[Any], float] | None = None
                  ) -> pytest.MarkDecorator:
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

    Returns
    -------
    pytest.MarkDecorator
        ``pytest.mark.parametrize(argname, [pytest.param(key,
        marks=pytest.mark.points(w), id=key), ...])``.
    """
    if not datasets:
        raise ValueError("`datasets` must name at least one dataset.")

    def weight(value: Any) -> float:
        if points is None:
            return float(getattr(value, "points", 1))
        return float(points(value) if callable(points) else points)

    params = [pytest.param(key, marks=pytest.mark.points(weight(value)), id=key)
              for key, value in datasets.items()]
    return pytest.mark.parametrize(argname, params)


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


# ---------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------


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
