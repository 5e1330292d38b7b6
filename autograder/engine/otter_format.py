"""Read an otter-grader "assign"-format master notebook: questions, test cases, points.

otter-grader 7 (``otter assign``) marks a master notebook with raw cells holding
YAML: ``# ASSIGNMENT CONFIG`` once, then per question ``# BEGIN QUESTION`` (``name``,
``points``, ``all_or_nothing``, ``manual``) ... ``# END QUESTION``, with
``# BEGIN SOLUTION`` / ``# END SOLUTION`` around the solution cells and
``# BEGIN TESTS`` / ``# END TESTS`` around the test cells. A test cell is hidden
when its first line is a comment holding the word ``hidden`` or its
``# BEGIN TEST CONFIG`` ... ``# END TEST CONFIG`` block (a string of YAML at the top of
the cell) says ``hidden: true``;
that block may also give the case's ``points``.

This module reads such a notebook with nbformat and turns every test case into an
:class:`~autograder.engine.celltests.CellTest` that runs after the student's last
cell, as ``otter run`` does, with otter's points. otter has two formats for test
cases, both read here:

* OK format (otter's default, ``tests: ok_format: true``): the cell's code is a
  doctest whose expected output is the output *saved in the master notebook*;
  the case passes when every example prints what was saved.
* exception format (``ok_format: false``): the cell defines one function; the case
  passes when calling it (its arguments looked up by name in the student's
  globals, ``env`` being the globals themselves) raises nothing.

The parsing follows otter 7's own code (``otter/assign/blocks.py``,
``tests_manager.py``, ``test_files/abstract_test.py``) rule for rule; it is written
here because otter is not a dependency of the grader and its parser is tied to
``otter assign``'s output writers. Every mistake raises
:class:`~autograder.errors.AssignmentError` naming the cell and what to do.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import nbformat

from autograder.engine.celltests import CellTest
from autograder.errors import AssignmentError, UsageError

__all__ = ["OtterCase", "OtterQuestion", "OtterNotebook", "is_otter_notebook", "read_otter",
           "case_points", "otter_cell_tests", "checker_tests", "read_requirements_file",
           "doctest_text", "runnable_source", "otter_parts", "CONFIG", "BOUNDARY"]

#: the first line of otter's config cell, and of its block boundaries (``# BEGIN TESTS``)
CONFIG = re.compile(r"#\s+ASSIGNMENT\s+CONFIG", re.IGNORECASE)
BOUNDARY = re.compile(r"#\s+(BEGIN|END)\s+(QUESTION|PROMPT|SOLUTION|TESTS)\s*", re.IGNORECASE)
# otter's BEGIN_TEST_CONFIG_REGEX / END_TEST_CONFIG_REGEX (assign/tests_manager.py)
_BEGIN_TEST_CONFIG = re.compile(r'(?:.\s*=\s*)?""?"?\s*#\s*BEGIN\s*TEST\s*CONFIG', re.IGNORECASE)
_END_TEST_CONFIG = re.compile(r'""?"?\s*#\s*END\s*TEST\s*CONFIG', re.IGNORECASE)
_QUESTION_KEYS = ("name", "manual", "points", "check_cell", "export", "all_or_nothing")
_CASE_KEYS = ("hidden", "points", "success_message", "failure_message")
_HELP = "See https://otter-grader.readthedocs.io/en/latest/otter_assign/v1/notebook_format.html."


@dataclass(frozen=True)
class OtterCase:
    """One test case (one test cell) of a question.

    ``source`` is the test's code without its config block; ``output`` the output
    the master notebook saved for the cell (the OK format's expected text).
    """

    source: str
    output: str
    hidden: bool
    points: float | None
    cell: int


@dataclass(frozen=True)
class OtterQuestion:
    """One ``# BEGIN QUESTION`` block: its YAML config and its test cases."""

    name: str
    points: Any
    all_or_nothing: bool
    manual: bool
    check_cell: bool
    cases: tuple[OtterCase, ...]


@dataclass(frozen=True)
class OtterNotebook:
    """A parsed master notebook."""

    path: Path
    config: dict[str, Any]
    questions: tuple[OtterQuestion, ...]

    @property
    def ok_format(self) -> bool:
        tests = self.config.get("tests") or {}
        return bool(tests.get("ok_format", True)) if isinstance(tests, dict) else True


# -- recognising and reading -------------------------------------------------------

def _yaml() -> Any:
    """PyYAML, imported when an otter notebook is read (the student's install has none)."""
    try:
        import yaml
    except ImportError:
        raise UsageError("Reading an otter-grader assignment needs PyYAML, which is not "
                         "installed: python -m pip install \"numgrade[instructor]\" (or "
                         "python -m pip install pyyaml).") from None
    return yaml


def _first_line(cell: Any) -> str:
    lines = str(cell.get("source", "")).splitlines()
    return lines[0] if lines else ""


def _unfenced(cell: Any) -> Any:
    """otter's ``extract_fenced_otter_cell``: a Markdown cell holding only an ```otter block."""
    if cell.get("cell_type") != "markdown":
        return cell
    lines = str(cell.get("source", "")).strip().splitlines()
    if len(lines) >= 2 and lines[0].strip() == "```otter" and lines[-1].strip() == "```" \
            and all(line.strip() != "```" for line in lines[1:-1]):
        return nbformat.v4.new_raw_cell("\n".join(lines[1:-1]))
    return cell


def _is_marker(cell: Any) -> bool:
    cell = _unfenced(cell)
    line = _first_line(cell)
    return cell.get("cell_type") == "raw" and bool(CONFIG.match(line) or BOUNDARY.match(line))


def is_otter_notebook(path: Path) -> bool:
    """True when ``path`` is a notebook with otter's ASSIGNMENT CONFIG or BEGIN QUESTION cells.

    Kept per file while its size and modification time stay the same: every load of an
    assignment asks (a grading process loads its assignment for every job), and reading
    a notebook with nbformat costs about 3 ms.
    """
    try:
        stat = path.stat()
    except OSError:
        return False
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    known = _OTTER_FILES.get(key)
    if known is None:
        try:
            nb = nbformat.read(str(path), as_version=4)
        except Exception:  # nbformat raises many types; the nbgrader reader reports the damage
            return False
        known = _OTTER_FILES[key] = any(_is_marker(cell) for cell in nb.cells)
        if len(_OTTER_FILES) > 256:  # a long-lived process that saw many notebooks
            _OTTER_FILES.pop(next(iter(_OTTER_FILES)))
    return known


#: (path, mtime in ns, size) -> whether it is an otter master notebook
_OTTER_FILES: dict[tuple[str, int, int], bool] = {}


def read_otter(path: Path) -> OtterNotebook:
    """Parse the master notebook ``path``.

    Raises
    ------
    AssignmentError
        A block that is not closed or is nested where otter forbids it, YAML that
        does not parse, a question without a name, a test cell with bad syntax, an
        OK-format test cell without its saved output, points otter would refuse.
    """
    try:
        nb = nbformat.read(str(path), as_version=4)
    except Exception as exc:  # nbformat raises many types on a damaged file
        raise AssignmentError(f"The master notebook {path} cannot be read: {exc}. "
                              "Open it in Jupyter and save it.") from None
    parser = _Parser(path)
    for number, cell in enumerate(nb.cells, start=1):
        parser.feed(number, _unfenced(cell))
    return parser.finish()


class _Parser:
    """Walks the cells once, keeping the open block (question, solution, tests, prompt)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.config: dict[str, Any] = {}
        self.has_config = False
        self.questions: list[OtterQuestion] = []
        self.question: dict[str, Any] | None = None
        self.cases: list[OtterCase] = []
        self.block: str | None = None  # "solution", "tests" or "prompt" inside a question
        self.opened_at = 0

    def error(self, number: int, what: str) -> AssignmentError:
        return AssignmentError(f"{self.path}: cell {number}: {what} {_HELP}")

    def feed(self, number: int, cell: Any) -> None:
        line = _first_line(cell)
        if cell.get("cell_type") == "raw" and CONFIG.match(line):
            if self.has_config:
                raise self.error(number, "a second '# ASSIGNMENT CONFIG' cell; keep one.")
            self.config, self.has_config = self.yaml(number, cell, "the ASSIGNMENT CONFIG"), True
            return
        boundary = BOUNDARY.match(line) if cell.get("cell_type") == "raw" else None
        if boundary:
            self.boundary(number, boundary.group(1).lower(), boundary.group(2).lower(), cell)
        elif self.block == "tests":
            if cell.get("cell_type") == "code":
                self.cases.append(self.case(number, cell))

    def yaml(self, number: int, cell: Any, what: str) -> dict[str, Any]:
        text = "\n".join(str(cell.get("source", "")).splitlines()[1:])
        yaml = _yaml()
        try:
            value = yaml.safe_load(text) if text.strip() else {}
        except yaml.YAMLError as exc:
            raise self.error(number, f"{what} is not valid YAML ({exc}); fix it.") from None
        if not isinstance(value, dict):
            raise self.error(number, f"{what} must be YAML keys and values; got {value!r}.")
        return value

    def boundary(self, number: int, edge: str, kind: str, cell: Any) -> None:
        if kind == "question":
            if edge == "begin":
                self.begin_question(number, cell)
            else:
                self.end_question(number)
            return
        if self.question is None:
            raise self.error(number, f"'# {edge.upper()} {kind.upper()}' outside a question; "
                                     "put it between '# BEGIN QUESTION' and '# END QUESTION'.")
        if edge == "begin":
            if self.block is not None:
                raise self.error(number, f"'# BEGIN {kind.upper()}' inside the {self.block} "
                                         f"block opened at cell {self.opened_at}; close that first.")
            self.block, self.opened_at = kind, number
        elif self.block != kind:
            raise self.error(number, f"'# END {kind.upper()}' without '# BEGIN {kind.upper()}'.")
        else:
            self.block = None

    def begin_question(self, number: int, cell: Any) -> None:
        if self.question is not None:
            raise self.error(number, f"a question begins inside the question opened at cell "
                                     f"{self.opened_at}; add '# END QUESTION' before it.")
        config = self.yaml(number, cell, "the BEGIN QUESTION config")
        unknown = sorted(set(config) - set(_QUESTION_KEYS))
        if unknown:
            raise self.error(number, f"unknown question key(s) {', '.join(map(repr, unknown))}; "
                                     f"otter knows {', '.join(_QUESTION_KEYS)}.")
        if not isinstance(config.get("name"), str) or not config["name"].strip():
            raise self.error(number, "the question has no 'name'; add 'name: q1' to its config.")
        if any(q.name == config["name"] for q in self.questions):
            raise self.error(number, f"a second question named {config['name']!r}; names must "
                                     "be unique.")
        self.question, self.cases, self.opened_at = config, [], number

    def end_question(self, number: int) -> None:
        if self.question is None:
            raise self.error(number, "'# END QUESTION' without '# BEGIN QUESTION'.")
        if self.block is not None:
            raise self.error(number, f"the {self.block} block opened at cell {self.opened_at} "
                                     f"is not closed; add '# END {self.block.upper()}'.")
        config = self.question
        question = OtterQuestion(
            name=config["name"], points=config.get("points"),
            all_or_nothing=bool(config.get("all_or_nothing", False)),
            manual=bool(config.get("manual", False)),
            check_cell=bool(config.get("check_cell", True)), cases=tuple(self.cases))
        case_points(question, where=f"{self.path}: question {question.name!r}")  # refuse bad points now
        self.questions.append(question)
        self.question, self.cases = None, []

    def case(self, number: int, cell: Any) -> OtterCase:
        """otter's ``AssignmentTestsManager.read_test``, for one test cell."""
        lines = str(cell.get("source", "")).split("\n")
        try:
            ast.parse("\n".join(lines))
        except SyntaxError as exc:
            raise self.error(number, f"the test cell is not valid Python ({exc.msg}, line "
                                     f"{exc.lineno}); fix it.") from None
        hidden = lines[0].lstrip().startswith("#") and bool(
            re.search(r"\bhidden\b", lines[0], flags=re.IGNORECASE))
        start = 0 if hidden else -1
        config: dict[str, Any] = {}
        if _BEGIN_TEST_CONFIG.match(lines[0]):
            end = next((i for i, line in enumerate(lines) if _END_TEST_CONFIG.match(line)), None)
            if end is None:
                raise self.error(number, "the TEST CONFIG block has no '\"\"\" # END TEST CONFIG' "
                                         "line; add it.")
            yaml = _yaml()
            try:
                config = yaml.safe_load("\n".join(lines[1:end])) or {}
            except yaml.YAMLError as exc:
                raise self.error(number, f"the TEST CONFIG is not valid YAML ({exc}).") from None
            if not isinstance(config, dict) or set(config) - set(_CASE_KEYS):
                raise self.error(number, f"the TEST CONFIG may hold only {', '.join(_CASE_KEYS)}; "
                                         f"got {config!r}.")
            start = end
        points = config.get("points")
        if points is not None and (isinstance(points, bool) or not isinstance(points, (int, float))):
            raise self.error(number, f"the test's points must be a number; got {points!r}.")
        source = "\n".join(lines[start + 1:])
        return OtterCase(source=source, output=_saved_output(cell),
                         hidden=bool(config.get("hidden", hidden)),
                         points=None if points is None else float(points), cell=number)

    def finish(self) -> OtterNotebook:
        if self.question is not None:
            raise AssignmentError(f"{self.path}: the question opened at cell {self.opened_at} "
                                  f"is not closed; add a raw cell '# END QUESTION'. {_HELP}")
        otter = OtterNotebook(path=self.path, config=self.config, questions=tuple(self.questions))
        if otter.ok_format:
            for question in otter.questions:
                for case in question.cases:
                    _require_output(self.path, question.name, case)
        return otter


def _saved_output(cell: Any) -> str:
    """The cell's saved output as otter reads it (``read_test``): stream text and text/plain."""
    output = ""
    for item in cell.get("outputs", []):
        output += "".join(item.get("text", ""))
        plain = item.get("data", {}).get("text/plain")
        if plain and isinstance(plain, list):
            output += plain[0]
        elif plain:
            output += plain
    return output


def _require_output(path: Path, question: str, case: OtterCase) -> None:
    """An OK-format test ending in a bare expression needs the output it was saved with."""
    body = ast.parse(case.source).body
    if case.output or not body or not isinstance(body[-1], ast.Expr) \
            or isinstance(body[-1].value, ast.Call):
        return
    raise AssignmentError(
        f"{path}: cell {case.cell} (a test of question {question!r}) has no saved output, and "
        "otter's OK format compares the test's output with the one saved in the master "
        "notebook: run the master notebook top to bottom and save it.")


# -- points (otter/test_files/abstract_test.py: resolve_test_file_points) -------------

def _question_total(question: OtterQuestion, where: str) -> float | list[float] | None:
    """otter's ``_create_test_file_info``: ``points: {each: x}`` means x per case."""
    points = question.points
    if isinstance(points, dict):
        each = points.get("each", 1)
        if isinstance(each, bool) or not isinstance(each, (int, float)):
            raise AssignmentError(f"{where}: points 'each' must be a number; got {each!r}.")
        return float(each) * len(question.cases)
    if isinstance(points, list):
        if len(points) != len(question.cases) or not all(
                isinstance(p, (int, float)) and not isinstance(p, bool) for p in points):
            raise AssignmentError(f"{where}: 'points' is a list of {len(points)} but the question "
                                  f"has {len(question.cases)} test cells; give one number per test.")
        return [float(p) for p in points]
    if points is None:
        return None
    if isinstance(points, bool) or not isinstance(points, (int, float)):
        raise AssignmentError(f"{where}: 'points' must be a number, a list or {{each: n}}; "
                              f"got {points!r}.")
    return float(points)


def case_points(question: OtterQuestion, *, where: str = "") -> tuple[float, ...]:
    """The points of each test case, as otter 7 resolves them.

    A list gives each case its points. A total is split evenly over the cases whose
    TEST CONFIG gives no points, after those that do. No total: the cases' own
    points, the others 0, or 1 point split evenly when no case gives any.
    """
    where = where or f"question {question.name!r}"
    total = _question_total(question, where)
    given = [c.points for c in question.cases]
    if isinstance(total, list):
        given, total = list(total), None
    fixed = sum(p for p in given if p is not None)
    unset = sum(1 for p in given if p is None)
    if total is not None:
        if fixed > total:
            raise AssignmentError(f"{where}: its test cases give {fixed:g} points, more than the "
                                  f"question's {total:g}; lower them or raise 'points'.")
        rest = (total - fixed) / unset if unset else 0.0
    elif fixed == 0 and all(p in (0, None) for p in given):
        rest = 1 / unset if unset else 0.0
    else:
        rest = 0.0
    return tuple(float(p) if p is not None else rest for p in given)


# -- what the worker runs -----------------------------------------------------------

class _AnnotationRemover(ast.NodeTransformer):
    """otter's ``_AnnotationRemover``: doctests cannot hold annotations."""

    def visit(self, node: Any) -> Any:
        self.generic_visit(node)
        for name in ("annotation", "returns", "type_params"):
            if hasattr(node, name):
                setattr(node, name, None)
        return node


def doctest_text(case: OtterCase) -> str:
    """The OK-format doctest otter writes for ``case`` (``str_to_doctest`` plus the output)."""
    code = ast.unparse(_AnnotationRemover().visit(ast.parse(case.source)))
    lines: list[str] = []
    for line in code.split("\n"):
        if not line:
            continue
        continued = (line.startswith((" ", "\t", "elif ", "else:", "finally:"))
                     or bool(re.match(r"^except[\s\w]*:", line))
                     or (bool(lines) and lines[-1].strip().endswith("\\")))
        lines.append(("... " if continued else ">>> ") + line)
    lines.extend(case.output.split("\n"))
    return "\n".join(lines)


# The OK-format case in the student's namespace, run as otter's ``run_doctest`` does
# (a DocTest over the globals, not cleared, its stdout and stderr captured), raising
# when an example fails. What the test writes to stderr (a warning) is otter's
# business of the report, never a failure: the cell-test wrapper's nbgrader rule
# (stderr means zero) must not apply to otter's tests.
_DOCTEST_RUNNER = '''\
def _numgrade_otter_case(text, name):
    import contextlib, doctest, io
    examples = [e for e in doctest.DocTestParser().parse(text, name)
                if isinstance(e, doctest.Example)]
    test = doctest.DocTest(examples, globals(), name, None, None, text)
    runner = doctest.DocTestRunner(verbose=False)
    report = io.StringIO()
    with contextlib.redirect_stdout(report), contextlib.redirect_stderr(report):
        runner.run(test, out=report.write, clear_globs=False)
    if runner.failures:
        raise AssertionError("Test case failed\\n" + report.getvalue())
try:
    _numgrade_otter_case({text!r}, {name!r})
finally:
    del _numgrade_otter_case
'''

# The exception-format case: otter's ``test_case.call_func`` (stderr kept away from
# the cell-test wrapper's nbgrader rule, as above).
_CALL_RUNNER = '''\
{source}
def _numgrade_otter_call(function):
    import contextlib, inspect, io
    env = globals()
    with contextlib.redirect_stderr(io.StringIO()):
        function(**{{arg: (env if arg == "env" else env.get(arg))
                    for arg in inspect.signature(function).parameters}})
try:
    _numgrade_otter_call({function})
finally:
    del _numgrade_otter_call, {function}
'''


def runnable_source(otter: OtterNotebook, question: str, number: int, case: OtterCase) -> str:
    """The code the worker runs for ``case``: raises when the case fails."""
    if otter.ok_format:
        return _DOCTEST_RUNNER.format(text=doctest_text(case), name=f"{question} {number - 1}")
    tree = ast.parse(case.source)
    if len(tree.body) > 2 or not tree.body or not isinstance(tree.body[0], ast.FunctionDef):
        raise AssignmentError(
            f"{otter.path}: cell {case.cell}: an exception-based test cell (tests: ok_format: "
            "false) holds one function definition and at most a call to it; split it.")
    function = tree.body[0]
    return _CALL_RUNNER.format(source=ast.unparse(function), function=function.name)


def otter_cell_tests(otter: OtterNotebook, notebook: str) -> tuple[CellTest, ...]:
    """The grading run's tests: every case of every autograded question, otter's points.

    A case is one :class:`CellTest` named as otter names it (``"q1 - 2"``); an
    ``all_or_nothing`` question is one test with all its cases (hidden if any is).
    Manual questions have no tests.
    """
    tests: list[CellTest] = []
    for question in otter.questions:
        if question.manual or not question.cases:
            continue
        points = case_points(question, where=f"{otter.path}: question {question.name!r}")
        sources = [runnable_source(otter, question.name, i, case)
                   for i, case in enumerate(question.cases, start=1)]
        if question.all_or_nothing:
            tests.append(CellTest(name=question.name, notebook=notebook, points=sum(points),
                                  source="\n".join(sources),  # every case must pass
                                  hidden=any(c.hidden for c in question.cases)))
            continue
        tests.extend(CellTest(name=f"{question.name} - {i}", notebook=notebook, points=pts,
                              source=src, hidden=case.hidden)
                     for i, (case, pts, src) in enumerate(zip(question.cases, points, sources),
                                                          start=1))
    return tuple(tests)


def checker_tests(otter: OtterNotebook) -> dict[str, Any]:
    """What ``grader.check`` in the worker is given: the public cases only, by question.

    ``{"questions": {name: [{"name": "q1 - 1", "source": ...}, ...]}}``; a question
    whose cases are all hidden is listed with none, so its check cell says so. No
    hidden case is in it.
    """
    questions: dict[str, list[dict[str, str]]] = {}
    for question in otter.questions:
        if question.manual:
            continue
        questions[question.name] = [
            {"name": f"{question.name} - {i}",
             "source": runnable_source(otter, question.name, i, case)}
            for i, case in enumerate(question.cases, start=1) if not case.hidden]
    return {"questions": questions}


def read_requirements_file(otter: OtterNotebook, root: Path) -> tuple[str, ...]:
    """The ASSIGNMENT CONFIG's ``requirements`` file, else ``requirements.txt`` beside it.

    One requirement a line; blank lines and ``#`` comments are skipped. ``otter-grader``
    itself is dropped: the worker has its own ``otter`` stand-in.
    """
    named = otter.config.get("requirements")
    if named is not None and not isinstance(named, str):
        raise AssignmentError(f"{otter.path}: ASSIGNMENT CONFIG requirements must be the path "
                              f"of a requirements.txt file; got {named!r}.")
    path = (otter.path.parent / named) if named else otter.path.parent / "requirements.txt"
    if not path.is_file():
        if named:
            raise AssignmentError(f"{otter.path}: ASSIGNMENT CONFIG names the requirements file "
                                  f"{named!r}, which is not in {otter.path.parent}; add it.")
        return ()
    if not path.resolve().is_relative_to(root):
        raise AssignmentError(f"{otter.path}: the requirements file {named!r} must be inside "
                              f"{root}.")
    found = []
    for line in path.read_text(encoding="utf-8").splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        if line.startswith("-"):
            raise AssignmentError(f"{path}: {line!r}: only requirements (name and version) are "
                                  "read, not pip options; list the packages one a line.")
        if re.split(r"[\s<>=!~\[;]", line, maxsplit=1)[0].lower() not in ("otter-grader", "otter_grader"):
            found.append(line)
    return tuple(found)


def otter_parts(root: Path, notebook: Path) -> tuple[tuple[CellTest, ...], tuple[str, ...]] | None:
    """The cell tests and requirements of an otter master notebook; None for other notebooks."""
    if not is_otter_notebook(notebook):
        return None
    otter = read_otter(notebook)
    return otter_cell_tests(otter, notebook.name), read_requirements_file(otter, root)
