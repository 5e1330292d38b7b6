"""One pytest session per grader: the checks are collected once and re-run for every submission.

Starting ``pytest.main`` for every submission was most of the grader's own time on
a small assignment (configuration, plugins, importing and collecting the checks).
:class:`CheckSuite` configures pytest and collects the checks once, then runs the
collected items for each submission through pytest's per-item phases (setup, call,
teardown, with their hooks; the reporting around them is left out: :func:`_run_item`).
Nothing of one student reaches the next: every fixture of every scope is torn down at the
end of each run, the check modules' globals and the items' parameters are put back
as they were right after collection before each run (see :class:`_Pristine` for
what cannot be), and the grading plugin is pointed at the new submission.

Why the session is driven from here rather than by ``pytest.main`` running once in a
thread that takes submissions from a queue: the checks then run in the caller's
thread, so Ctrl-C (which Python delivers to the main thread only) still stops a
check, and every error is raised in the caller's stack rather than ferried between
threads. The steps are those of ``_pytest.main.wrap_session``, through public hooks,
except three internal pieces pytest offers no public form of (named where used).
"""

from __future__ import annotations

import contextlib
import copy
import functools
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from types import BuiltinFunctionType, FunctionType, ModuleType
from typing import Any, Callable, Iterable, Iterator, Sequence

import pytest

# Internal to pytest: what pytest.main uses to build a Config from arguments and
# plugin objects, and the error it raises for a conftest.py that cannot be imported.
from _pytest.config import ConftestImportFailure, _prepareconfig
from _pytest.runner import runtestprotocol
from _pytest.warnings import catch_warnings_for_item

from autograder.engine.plugin import CheckContext, GradingPlugin
from autograder.errors import AssignmentError, EngineError
from autograder.results.model import CheckResult


def pytest_args(files: Sequence[Path], rootdir: Path) -> list[str]:
    """The options of every check run: quiet, no cache, no third-party plugin, plain asserts."""
    return [str(f) for f in files] + [
        # --confcutdir: a conftest.py above the assignment is never imported into the grader.
        "-c", os.devnull, "--rootdir", str(rootdir), "--confcutdir", str(rootdir),
        # --capture=sys: a check's prints stay out of the grader's output, kept in memory
        # (fd capture read a temporary file after every phase of every item; the
        # verdict never comes from captured output).
        "-p", "no:cacheprovider", "--capture=sys",
        "-p", "no:terminal", "-p", "no:stepwise", "-p", "no:unraisableexception",
        "-p", "no:threadexception", "-p", "no:pastebin", "-p", "no:junitxml", "-p", "no:doctest",
        "--assert=plain", "--import-mode=importlib",
        "-W", "ignore::pytest.PytestAssertRewriteWarning",
    ]


@dataclass(frozen=True)
class CheckRun:
    """What one submission's run of the checks recorded."""

    results: tuple[CheckResult, ...]
    instructor_log: tuple[str, ...]


class CheckSuite:
    """The checks of one assignment, configured and collected once, run per submission.

    Raises :class:`AssignmentError` when the checks cannot be collected (nothing of
    the session is left behind). After a run that raised, the session is
    :attr:`broken` and must be closed; a grader then collects a new one.
    """

    def __init__(self, files: Sequence[Path], rootdir: Path, *, name: str,
                 context: CheckContext) -> None:
        self.name = name
        self.broken = False
        self.plugin = GradingPlugin(context)
        self._checks = rootdir / "checks"
        self._tops = _tops(self._checks)
        self._helpers = str(rootdir / "checks" / "public")
        self._config: pytest.Config | None = None
        self._session: pytest.Session | None = None
        self._started = False  # pytest_sessionstart was called: pytest_sessionfinish is due
        # Check modules are imported afresh for a new session: an edited check is never
        # run from an old copy, and one that failed to import fails again.
        forget_check_modules(self._checks)
        try:
            with self._environment():
                self._start(files, rootdir)
            assert self._session is not None
            self.items: tuple[pytest.Item, ...] = tuple(self._session.items)
            assert self._config is not None
            self._light = _only_pytest_s_own_protocol(self._config)
            # The modules stay out of sys.modules between runs (see _installed_modules).
            self._modules = {n: m for n, m in sys.modules.items()
                             if _is_check_module(n, m, self._tops)}
            self._pristine = _Pristine(self._modules.values(), self.items)
        except BaseException:
            self.discard()
            raise
        finally:
            forget_check_modules(self._checks)

    def _start(self, files: Sequence[Path], rootdir: Path) -> None:
        """Configure pytest, start the session and collect: ``wrap_session`` up to the run loop."""
        try:
            config = _prepareconfig(pytest_args(files, rootdir), plugins=[self.plugin])
        except ConftestImportFailure as exc:
            raise AssignmentError(f"The checks of assignment {self.name!r} could not be "
                                  f"collected; fix them before grading:\n{exc}") from exc
        except pytest.UsageError as exc:
            raise EngineError(f"pytest refused the check run's options: {exc}") from exc
        self._config = config
        self._session = session = pytest.Session.from_config(config)
        session.exitstatus = pytest.ExitCode.OK
        # Internal to pytest (Config._do_configure): wrap_session's own step between
        # building the Config and starting the session; it calls pytest_configure.
        config._do_configure()
        try:
            config.hook.pytest_sessionstart(session=session)
            self._started = True
            config.hook.pytest_collection(session=session)
        except Exception as exc:  # pytest.main answered these with a status, not a verdict
            raise EngineError(f"the checks could not be collected ({type(exc).__name__}: "
                              f"{exc}); nothing was graded") from exc
        errors = self.plugin.collection_errors
        if not errors and not session.items:
            errors.append("no checks were collected")
        if errors:  # pytest reports these as an interrupted run
            raise AssignmentError(
                f"The checks of assignment {self.name!r} could not be collected; "
                "fix them before grading:\n" + "\n".join(errors))

    # -- one submission --------------------------------------------------------
    def run(self, context: CheckContext) -> CheckRun:
        """Run every collected item for ``context``'s submission, from fresh state.

        Raises :class:`EngineError` when the run ends early or records fewer verdicts
        than items, and KeyboardInterrupt on Ctrl-C (or a check's ``pytest.exit()``):
        a partial run is never a result. Either way the session is then broken.
        """
        if self.broken or self._config is None:
            raise EngineError("this check session was closed after an earlier failure")
        self.broken = True  # until the run ends cleanly: fixtures may still be set up
        try:
            self._pristine.restore()
            self.plugin.begin(context)
            with self._environment(), self._installed_modules():
                self._run_items()
        except pytest.exit.Exception as exc:  # pytest.main reported this as "interrupted"
            if exc.returncode in (None, pytest.ExitCode.INTERRUPTED):
                raise KeyboardInterrupt from exc
            raise self._ended_early(f"pytest.exit({exc.returncode})") from exc
        except (EngineError, KeyboardInterrupt):
            raise
        except Exception as exc:  # pytest's or a plugin's own failure, not a check's
            raise self._ended_early(f"{type(exc).__name__}: {exc}") from exc
        self.broken = False
        return CheckRun(tuple(self.plugin.results), tuple(self.plugin.instructor_log))

    def _run_items(self) -> None:
        """``pytest_runtestloop``'s loop, with ``nextitem=None`` after the last item so that
        every fixture, session-scoped ones included, is torn down at the end of the run."""
        assert self._config is not None and self._session is not None
        hook, session, items = self._config.hook, self._session, self.items
        start = os.getcwd()
        try:
            for index, item in enumerate(items):
                # Internal to pytest: each phase's captured output is appended to the
                # item; runs of a long session would pile them up (the verdict is
                # recorded by the plugin, never read from there).
                sections = getattr(item, "_report_sections", None)
                if isinstance(sections, list):
                    sections.clear()
                nextitem = items[index + 1] if index + 1 < len(items) else None
                if self._light:
                    _run_item(item, nextitem)
                else:  # a conftest.py takes part in the protocol: pytest's own, in full
                    hook.pytest_runtest_protocol(item=item, nextitem=nextitem)
                if session.shouldfail or session.shouldstop:
                    raise self._ended_early(f"stopped: {session.shouldfail or session.shouldstop}")
        finally:
            if os.getcwd() != start:  # as pytest.main does after its run
                os.chdir(start)
        if len(self.plugin.results) != len(items):
            raise self._ended_early(f"{len(self.plugin.results)} of {len(items)} checks recorded")

    def _ended_early(self, why: str) -> EngineError:
        return EngineError(f"the check run ended early ({why}); nothing was stored, and the "
                           "submission is graded again on the next run")

    # -- the session's life ----------------------------------------------------
    def close(self) -> None:
        """Tear down what is still set up and unconfigure pytest (capture, plugins, warnings)."""
        config, session = self._config, self._session
        self._config = self._session = None
        if config is None:
            return
        with self._environment():
            try:
                if session is not None and self._started:
                    config.hook.pytest_sessionfinish(session=session,
                                                     exitstatus=session.exitstatus)
            finally:
                # Internal to pytest (Config._ensure_unconfigure): wrap_session's last step;
                # it calls pytest_unconfigure and the config's cleanups.
                config._ensure_unconfigure()

    def discard(self) -> None:
        """Close a session that failed, without hiding the failure being handled.

        Its fixtures' finalizers may fail in turn (they ran half a check); that is
        not what went wrong, and the error that broke the session is already raised.
        """
        self.broken = True
        try:
            self.close()
        except Exception:  # see the docstring: the original failure is the one reported
            pass

    # -- what each run sees ----------------------------------------------------
    @contextlib.contextmanager
    def _environment(self) -> Iterator[None]:
        """What pytest.main gave every check run: pytest's environment variables, no outer
        assertion rewriter, and the helpers released beside the public checks importable."""
        sys.path.insert(0, self._helpers)
        try:
            with _without_assertion_rewriting(), _checks_environment():
                yield
        finally:
            with contextlib.suppress(ValueError):
                sys.path.remove(self._helpers)

    @contextlib.contextmanager
    def _installed_modules(self) -> Iterator[None]:
        """The session's check modules in ``sys.modules`` for a run, and out of it after.

        During a run they are where the run that imported them would leave them (a
        check that imports a helper by name gets the one collected); between runs
        they are gone, so another assignment's grader in this process (whose checks
        may have the same module names) never meets them.
        """
        before = set(sys.modules)
        sys.modules.update(self._modules)
        try:
            yield
        finally:
            for name, module in self._modules.items():
                if sys.modules.get(name) is module:
                    del sys.modules[name]
            for name in set(sys.modules) - before:  # imported by a check during the run
                if _is_check_module(name, sys.modules[name], self._tops):
                    del sys.modules[name]


#: the hooks around an item that _run_item leaves out, and the pytest modules whose
#: implementations of them it stands for (see there)
_PROTOCOL_HOOKS = ("pytest_runtest_protocol", "pytest_runtest_logstart",
                   "pytest_runtest_logreport", "pytest_runtest_logfinish")
_LEFT_OUT = ("_pytest.runner", "_pytest.warnings", "_pytest.assertion", "_pytest.faulthandler",
             "_pytest.unittest", "_pytest.logging", "_pytest.main", "_pytest.python",
             "_pytest.junitxml", "_pytest.terminal", "_pytest.resultlog", "_pytest.reports",
             "_pytest.stepwise", "_pytest.pytester")


def _only_pytest_s_own_protocol(config: pytest.Config) -> bool:
    """Whether only pytest's own plugins implement the hooks :func:`_run_item` leaves out.

    A ``conftest.py`` (or any other plugin) that implements one of them, to take an
    item over or to watch its reports, gets pytest's full protocol instead.
    """
    for name in _PROTOCOL_HOOKS:
        for impl in getattr(config.hook, name).get_hookimpls():
            module = getattr(impl.plugin, "__name__", None) or type(impl.plugin).__module__
            if not isinstance(module, str) or module.split(".")[0] != "_pytest" \
                    or ".".join(module.split(".")[:2]) not in _LEFT_OUT:
                return False
    return True


def _run_item(item: pytest.Item, nextitem: pytest.Item | None) -> None:
    """One item through pytest's setup, call and teardown, without the reporting around them.

    ``pytest_runtest_protocol`` would add, per item, the log hooks
    (``pytest_runtest_logstart``, ``logreport`` per phase, ``logfinish``) that only
    reporters use (none is loaded: the grading plugin records verdicts from
    ``pytest_runtest_makereport``), and the wrappers of the plugins around the whole
    protocol: of those only the warnings plugin's changes how a check runs (filters,
    ``@pytest.mark.filterwarnings``), so it is kept here; the assertion plugin's only
    serves rewritten asserts (the checks run with ``--assert=plain``) and the
    faulthandler's only a ``faulthandler_timeout``, which the options never set.
    Every phase still goes through the hooks that run fixtures, marks and captures.
    """
    # Internal to pytest: runtestprotocol is pytest_runtest_protocol's body, and
    # catch_warnings_for_item the warnings plugin's wrapper of it.
    with catch_warnings_for_item(config=item.config, ihook=item.ihook, when="runtest",
                                 item=item):
        runtestprotocol(item, nextitem=nextitem, log=False)


class _Pristine:
    """The check modules' globals and the items' parameters as collected, given afresh per run.

    Before every run, each module's namespace is cleared and refilled with deep copies
    of the values it held right after collection, and each item's parameter values
    likewise (one memo for all of them, so a global and a parameter that were one
    object stay one object). So a check that appends to a module-level list, rebinds
    a global, draws from a module-level random generator or sorts a dataset in place
    leaves nothing for the next submission. Functions cached with ``functools.cache``
    or ``lru_cache`` are emptied, as a fresh import would have them.

    Not restored (documented in docs/writing-an-assignment.md): a value deepcopy
    cannot copy (a module, a lock, an open file, an object holding one) is put back
    as the same object, so a change made inside it stays; likewise class attributes,
    function defaults and closures, and the state of modules outside ``checks/``.
    """

    def __init__(self, modules: Iterable[ModuleType], items: Sequence[pytest.Item]) -> None:
        memo: dict[int, Any] = {}
        self._modules = [(m.__dict__, [(k, *_copy_or_keep(k, v, memo)) for k, v in
                                       m.__dict__.items()]) for m in modules]
        self._params = [(item.callspec.params,
                         [(k, *_copy_or_keep(k, v, memo)) for k, v in item.callspec.params.items()])
                        for item in items if getattr(item, "callspec", None) is not None]
        self._caches: list[Callable[[], None]] = [
            v.cache_clear for m in modules for v in m.__dict__.values()
            if callable(v) and hasattr(v, "cache_clear") and hasattr(v, "cache_info")]

    def restore(self) -> None:
        memo: dict[int, Any] = {}
        for namespace, entries in self._modules:
            fresh = {k: copy.deepcopy(v, memo) if copied else v for k, v, copied in entries}
            namespace.clear()
            namespace.update(fresh)
        for params, entries in self._params:
            params.update({k: copy.deepcopy(v, memo) if copied else v for k, v, copied in entries})
        for clear in self._caches:
            clear()


#: values never copied: deepcopy returns them as they are, or they are pytest's own
_KEPT_TYPES = (ModuleType, type, FunctionType, BuiltinFunctionType)


def _copy_or_keep(name: str, value: Any, memo: dict[int, Any]) -> tuple[Any, bool]:
    """A pristine deep copy of ``value`` and True, or ``value`` itself and False.

    Dunder names (``__builtins__``, ``__spec__``...), functions, classes, modules and
    pytest's own objects (fixture definitions, marks) are kept; a value that cannot
    be copied is kept, and the memo loses what the failed copy left half-made.
    """
    if (name.startswith("__") and name.endswith("__")) or isinstance(value, _KEPT_TYPES) or \
            type(value).__module__.split(".")[0] in ("_pytest", "pytest", "pluggy"):
        return value, False
    size = len(memo)
    try:
        return copy.deepcopy(value, memo), True
    except Exception:  # not copyable: documented as not restored (see _Pristine)
        for key in list(memo)[size:]:
            del memo[key]
        return value, False


def forget_check_modules(*folders: Path) -> None:
    """Drop every imported module of the checks in ``folders`` (and their helpers).

    pytest's ``--import-mode=importlib`` names a check module by its place in the
    assignment (``checks.hidden.test_hull_hidden``, with ``checks`` and
    ``checks.hidden`` as file-less parents) and reuses a module of that name found
    in ``sys.modules``; dropping them makes the next collection import what is on disk.
    """
    tops = _tops(*folders)
    for name, module in list(sys.modules.items()):
        if _is_check_module(name, module, tops):
            del sys.modules[name]


def _tops(*folders: Path) -> tuple[str, ...]:
    return tuple({str(f) + os.sep for folder in folders for f in (folder, folder.resolve())})


def _is_check_module(name: str, module: Any, tops: tuple[str, ...]) -> bool:
    origin = getattr(module, "__file__", None)
    return name == "checks" or name.startswith("checks.") or (
        isinstance(origin, str)
        and (origin.startswith(tops) or _real_path(origin).startswith(tops)))


@functools.lru_cache(maxsize=8192)
def _real_path(path: str) -> str:
    """``os.path.realpath``, remembered: resolving the files of ~1,500 loaded modules
    twice per submission cost 100-200 ms. A module's file does not move while this
    process lives; a check file is matched by its own path first in any case."""
    return os.path.realpath(path)


@contextlib.contextmanager
def _without_assertion_rewriting() -> Iterator[None]:
    """When the grader itself runs inside pytest (an instructor's test-suite), that
    session's assertion rewriter would rewrite the checks and put their source in
    failure messages; it is taken out of the import system meanwhile."""
    hooks = [h for h in sys.meta_path if type(h).__name__ == "AssertionRewritingHook"]
    for hook in hooks:
        sys.meta_path.remove(hook)
    try:
        yield
    finally:
        sys.meta_path[0:0] = hooks


#: pytest's own environment variables, as the check run sees them: only the grading
#: plugin (third-party plugins cost start-up time and could change how checks run),
#: and none of the caller's options (a CI job's ``PYTEST_ADDOPTS=--junitxml=...``
#: would otherwise be an unknown option of the inner run and fail every grading).
_CHECKS_ENVIRONMENT: dict[str, str | None] = {
    "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1",
    "PYTEST_ADDOPTS": None,
    "PYTEST_PLUGINS": None,
    "PYTEST_DEBUG": None,
    "PYTEST_VERSION": pytest.__version__,  # pytest.main sets it for its run
}


@contextlib.contextmanager
def _checks_environment() -> Iterator[None]:
    """Set :data:`_CHECKS_ENVIRONMENT` for one check run; the caller's values come back after."""
    saved = {name: os.environ.get(name) for name in _CHECKS_ENVIRONMENT}

    def put(values: dict[str, str | None]) -> None:
        for name, value in values.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value

    put(_CHECKS_ENVIRONMENT)
    try:
        yield
    finally:
        put(saved)


__all__ = ["CheckRun", "CheckSuite", "forget_check_modules", "pytest_args"]
