"""The pytest plugin that turns an assignment's checks into verdicts on one submission.

Registered explicitly by :mod:`autograder.engine.checkrun` in the one pytest session
a grader keeps (never auto-loaded); :meth:`GradingPlugin.begin` points it at each
submission in turn. It provides the fixtures ``student``, ``credit``, ``rng``,
``feedback`` and ``variant``, the markers ``points`` and ``visibility``, and records one :class:`CheckResult` per
collected item. Like pytest-timeout, it lives in one readable module.
"""

from __future__ import annotations

import functools
import traceback
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from autograder.engine.proxy import CallLog, CallTarget, Student
from autograder.engine.variants import Variant
from autograder.errors import (
    CallTimeout,
    CheckFailure,
    ForbiddenUse,
    MissingFunction,
    NoVariant,
    NotRun,
    PartialCredit,
    StudentError,
    StudentException,
    UnsupportedValue,
    WorkerCrashed,
)
from autograder.results.model import Attachment, CheckResult

_KINDS: tuple[tuple[type[BaseException], str], ...] = (
    (ForbiddenUse, "forbidden"),
    (MissingFunction, "missing"),
    (StudentException, "exception"),
    (CallTimeout, "timeout"),
    (NotRun, "not-run"),
    (UnsupportedValue, "unsupported"),
    (WorkerCrashed, "crashed"),
    (StudentError, "crashed"),
)


class Credit:
    """Partial credit for a check: ``credit.partial(0.5, "correct but clockwise")``."""

    def partial(self, fraction: float, message: str) -> None:
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"`fraction` must lie in [0, 1]; got {fraction}.")
        raise PartialCredit(fraction, message)


@dataclass
class Feedback:
    """Pictures a check attaches to its result (written next to results.json)."""

    folder: Path | None
    check: str
    attachments: list[Attachment] = field(default_factory=list)
    #: what the check says it gave the student's function (shown at the "input" level)
    shown_input: str = ""

    def input(self, text: str) -> None:
        """Describe the input of this check; checks marked ``visibility("input")`` show
        this text instead of their message (never the expected value)."""
        self.shown_input = str(text)

    def image(self, label: str, png: bytes) -> None:
        if self.folder is None or not isinstance(png, (bytes, bytearray)):
            return
        if not bytes(png[:8]) == b"\x89PNG\r\n\x1a\n":
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        stem = "".join(c if c.isalnum() else "-" for c in f"{self.check}-{label}").strip("-")
        name = f"{stem[:80]}-{len(self.attachments)}.png"
        (self.folder / name).write_bytes(bytes(png))
        self.attachments.append(Attachment(label=label, filename=f"{self.folder.name}/{name}"))


@dataclass
class CheckContext:
    """What the plugin needs to know about the submission being graded."""

    target: CallTarget
    functions: tuple[str, ...]
    forbidden: dict[str, str]
    call_timeout: float
    seed: int
    hidden_root: Path | None
    attachments: Path | None = None
    #: the student's variant; None with ``has_variants``: the id is not on the roster
    variant: Variant | None = None
    has_variants: bool = False


#: what a student sees of a check (``@pytest.mark.visibility(LEVEL)``)
LEVELS = ("hidden", "after_deadline", "input", "visible")


class VariantView:
    """The ``variant`` fixture: the student's parameters, and a place to record outputs.

    ``variant["n"]`` is a parameter; ``variant.record("area", value)`` notes the
    student's output for a varied quantity, compared after grading against every
    roster variant's expected answers (answers that travel).
    """

    def __init__(self, variant: Variant) -> None:
        self.student, self.seed, self.params = variant.student, variant.seed, variant.as_dict()
        self.observed: dict[str, object] = {}

    def __getitem__(self, name: str) -> object:
        return self.params[name]

    def record(self, name: str, value: object) -> None:
        self.observed[str(name)] = value


def item_level(item: pytest.Item) -> str | None:
    marker = item.get_closest_marker("visibility")
    if marker is None:
        return None
    level = marker.args[0] if marker.args else marker.kwargs.get("level")
    if level not in LEVELS:
        raise ValueError(f"visibility must be one of {', '.join(LEVELS)}; got {level!r} "
                         f"on {item.nodeid}.")
    return str(level)


def check_name(item: pytest.Item) -> tuple[str, str | None]:
    """A readable name for an item: ``convex_hull[kettner-B2]``, and its dataset id."""
    base = getattr(item, "originalname", item.name)
    base = base[5:] if base.startswith("test_") else base
    callspec = getattr(item, "callspec", None)
    dataset = callspec.id if callspec is not None else None
    return (f"{base}[{dataset}]" if dataset else base), dataset


def item_points(item: pytest.Item) -> float:
    marker = item.get_closest_marker("points")
    if marker is None:
        return 1.0
    value = marker.args[0] if marker.args else marker.kwargs.get("n", 1.0)
    return float(value)


class GradingPlugin:
    """Fixtures, marker and verdicts for one submission at a time."""

    def __init__(self, context: CheckContext) -> None:
        self.collection_errors: list[str] = []
        #: items pytest collected; every one must end with a recorded verdict
        self.collected = 0
        self.begin(context)

    def begin(self, context: CheckContext) -> None:
        """Grade ``context``'s submission next: forget every verdict of the previous one.

        The plugin lives as long as the pytest session, which outlives submissions;
        everything that belongs to one submission is made afresh here.
        """
        self.context = context
        self.results: list[CheckResult] = []
        self.instructor_log: list[str] = []
        self._log = CallLog()
        self._feedback: Feedback | None = None
        self._seen: set[str] = set()
        self._variant: VariantView | None = None

    # -- configuration -----------------------------------------------------
    def pytest_configure(self, config: pytest.Config) -> None:
        config.addinivalue_line("markers", "points(n): points awarded by this check item")
        config.addinivalue_line("markers", "visibility(level): what a student sees of this "
                                "check: hidden, after_deadline, input or visible")

    def pytest_collection_finish(self, session: pytest.Session) -> None:
        self.collected = len(session.items)

    def pytest_collectreport(self, report: pytest.CollectReport) -> None:
        if report.failed:
            self.collection_errors.append(f"{report.nodeid}: {report.longreprtext[-3000:]}")

    # -- fixtures ----------------------------------------------------------
    @pytest.fixture
    def student(self) -> Student:
        """The submission's functions, called across the process boundary."""
        return Student(self.context.target, timeout=self.context.call_timeout,
                       functions=self.context.functions, forbidden=self.context.forbidden,
                       log=self._log)

    @pytest.fixture
    def credit(self) -> Credit:
        """Award part of a check's points with a message."""
        return Credit()

    @pytest.fixture
    def rng(self, request: pytest.FixtureRequest) -> np.random.Generator:
        """A generator seeded by the submission and the check, so regrades agree."""
        name, _ = check_name(request.node)
        return np.random.default_rng([self.context.seed, zlib.crc32(name.encode())])

    @pytest.fixture
    def feedback(self, request: pytest.FixtureRequest) -> Feedback:
        """Attach pictures to this check's result."""
        assert self._feedback is not None
        return self._feedback

    @pytest.fixture
    def variant(self) -> VariantView:
        """The student's variant; a person grades the check when the id has none."""
        if not self.context.has_variants:
            raise RuntimeError("The `variant` fixture needs a [variants] table in "
                               "assignment.toml; this assignment declares none.")
        if self.context.variant is None:
            raise NoVariant("This check needs your own parameters and your id is not on the "
                            "roster of this assignment's variants; a person will grade it.")
        self._variant = VariantView(self.context.variant)
        return self._variant

    # -- verdicts ----------------------------------------------------------
    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        self._log.names.clear()
        self._log.notes.clear()
        self._variant = None
        name, _ = check_name(item)
        self._feedback = Feedback(self.context.attachments, name)
        if hasattr(self.context.target, "current_check"):  # for "not run, because ..." messages
            self.context.target.current_check = f"`{name}`"

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo[None]) -> pytest.TestReport:
        """Record the verdict and answer with a bare report.

        pytest's own report would format the failing check's traceback with its
        source: costly (most of the grader's time on a wrong submission) and never
        shown, since the verdict and its message are recorded here.
        """
        exc = call.excinfo.value if call.excinfo is not None else None
        if call.when == "call" or (call.when == "setup" and exc is not None):
            self._record(item, exc)
        when = "setup" if call.when == "collect" else call.when
        return pytest.TestReport(item.nodeid, item.location, {},
                                 "passed" if exc is None else "failed",
                                 None if exc is None else "recorded by the grading plugin",
                                 when, duration=call.duration, start=call.start, stop=call.stop)

    def _record(self, item: pytest.Item, exc: BaseException | None) -> None:
        name, dataset = check_name(item)
        if name in self._seen:
            name = f"{Path(str(item.path)).stem}::{name}"
        self._seen.add(name)
        points = item_points(item)
        hidden = self._is_hidden(item)
        kind, fraction, message = self._verdict(exc, hidden, name)
        # the check's functions raised on the student's arguments: the student's error, but
        # an exception of an unusual type may be the check's bug, so the instructor sees it
        self.instructor_log.extend(f"{name}: {note}" for note in self._log.notes)
        self._log.notes.clear()
        attachments = tuple(self._feedback.attachments) if self._feedback else ()
        observed = tuple(self._variant.observed.items()) if self._variant else ()
        self.results.append(CheckResult(
            name=name, score=round(points * fraction, 6), max_score=points, output=message,
            hidden=hidden, kind=kind, dataset=dataset, attachments=attachments,
            level=item_level(item), shown_input=self._feedback.shown_input if self._feedback
            else "", observed=tuple((k, _plain(v)) for k, v in observed)))

    def _is_hidden(self, item: pytest.Item) -> bool:
        root = self.context.hidden_root
        return root is not None and _beneath(str(item.path), str(root))

    def _verdict(self, exc: BaseException | None, hidden: bool, name: str) -> tuple[str, float, str]:
        if exc is None:
            return "ok", 1.0, ""
        if isinstance(exc, NoVariant):
            return "needs-person", 0.0, str(exc)
        if isinstance(exc, PartialCredit):
            return "partial", exc.fraction, str(exc)
        for cls, kind in _KINDS:
            if isinstance(exc, cls):
                return kind, 0.0, _student_message(exc, hidden=hidden)
        if isinstance(exc, (CheckFailure, AssertionError)):
            return "wrong", 0.0, str(exc) or "This check failed."
        if isinstance(exc, pytest.skip.Exception):
            return "check-error", 0.0, "This check was skipped by the grader."
        self.instructor_log.append(f"{name}:\n" + "".join(
            traceback.format_exception(type(exc), exc, exc.__traceback__)))
        detail = "" if hidden else f": {type(exc).__name__}: {exc}"
        return ("check-error", 0.0,
                "The check could not use what your function returned" + detail +
                ". Make sure it returns exactly the type and shape the assignment asks for.")


def _plain(value: object) -> object:
    """A recorded output as plain data for results.json (arrays to lists, scalars to floats)."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return repr(value)[:200]
    return array.tolist() if array.size <= 10_000 else repr(value)[:200]


#: characters of the student's own exception message a hidden check may show
HIDDEN_EXCERPT = 80


@functools.lru_cache(maxsize=1024)
def _beneath(path: str, root: str) -> bool:
    """Whether ``path`` lies in ``root`` once both are resolved (cached: two resolves,
    a dozen system calls, for every item of every run otherwise)."""
    return Path(path).resolve().is_relative_to(Path(root).resolve())


def _student_message(exc: BaseException, *, hidden: bool) -> str:
    """The message for a failed call; for hidden checks, no traceback and a short excerpt.

    A student's exception message can repeat its arguments, and the arguments of
    hidden checks are the hidden data: they never reach the feedback whole.
    """
    if isinstance(exc, StudentException) and hidden and exc.exc_type:
        excerpt = exc.detail[:HIDDEN_EXCERPT] + ("..." if len(exc.detail) > HIDDEN_EXCERPT else "")
        return (f"{exc.function} raised {exc.exc_type} on this hidden input (your message, "
                f"first {HIDDEN_EXCERPT} characters: \u00ab{excerpt}\u00bb). Hidden inputs and "
                "tracebacks are not shown; reproduce it with inputs of your own.")
    message = str(exc)
    if isinstance(exc, StudentException) and exc.traceback:
        message += "\n\n" + exc.traceback
    return message
