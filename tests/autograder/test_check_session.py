"""One pytest session per grader: checks collected once, and nothing of one student in the next.

A small assignment whose checks keep state everywhere a check author might (module
globals rebound and mutated, a helper module's list, a module-level random
generator, a cached function, a parametrised value changed in place, a
session-scoped fixture) is graded A, B, A with one Grader: A's two results must
be identical, and B's own. Edits to the checks between gradings are picked up.
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.grader import Grader
from autograder.errors import AssignmentError, EngineError
from autograder.results.model import SubmissionResult
from tests.support.assignments import RIGHT, submission, write_double

HELPER = '''
REMEMBERED = []  # a helper module's global, appended to by the checks
'''

CHECKS = '''
import functools

import numpy as np
import pytest

from stateful_helper import REMEMBERED

SEEN = []                       # mutated in place
CALLS = 0                       # rebound
RNG = np.random.default_rng(7)  # its state advances with every draw
PAIR = [1, 2]                   # a parameter, changed in place by a check


@functools.cache
def answers_so_far():
    return []


@pytest.fixture(scope="session")
def tally():
    return {"answers": []}


@pytest.mark.points(2)
def test_double(student, tally):
    global CALLS
    CALLS += 1
    answer = student.double(21)
    SEEN.append(answer)
    REMEMBERED.append(answer)
    answers_so_far().append(answer)
    tally["answers"].append(answer)
    assert answer == 42, f"double(21) gave {answer}"


def test_state_is_this_submissions_own(tally):
    draw = int(RNG.integers(1_000_000))
    state = (CALLS, SEEN, REMEMBERED, answers_so_far(), tally["answers"])
    assert state == (1, SEEN[:1], SEEN[:1], SEEN[:1], SEEN[:1]) and len(SEEN) == 1, \\
        f"state carried over: {state}"
    assert SEEN[0] == 42, f"draw {draw}, state {state}"


@pytest.mark.parametrize("values", [PAIR], ids=["pair"])
def test_parameter_changed_in_place(student, values):
    values.append(student.double(1))
    assert values == [1, 2, 2], f"values {values}"
'''

WRONG = "def double(x):\n    return 3 * x\n"


def write_assignment(root: Path, name: str, checks: str = CHECKS) -> Path:
    return write_double(root, name, {"stateful_helper.py": HELPER, "test_double.py": checks})


def verdicts(result: SubmissionResult) -> list[tuple[str, float, float, str, str]]:
    return [(t.name, t.score, t.max_score, t.kind, t.output) for t in result.tests]


@pytest.fixture(scope="module")
def stateful(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Path, Grader]]:
    """One assignment and one Grader for the tests of this module: a Grader's warm
    worker costs seconds to start; each test leaves the checks as it found them."""
    folder = write_assignment(tmp_path_factory.mktemp("session"), "stateful")
    with Grader(load_assignment(folder)) as grader:
        yield folder, grader


@pytest.fixture
def right(tmp_path: Path) -> Path:
    return submission(tmp_path / "in", "a", RIGHT)


def restored(folder: Path) -> None:
    """Put the checks back as written, with a new mtime (a new session is collected)."""
    (folder / "checks" / "public" / "test_double.py").write_text(CHECKS)
    (folder / "checks" / "public" / "stateful_helper.py").write_text(HELPER)


def test_a_student_after_another_gets_the_same_result(
        stateful: tuple[Path, Grader], right: Path, tmp_path: Path) -> None:
    _, grader = stateful
    wrong = submission(tmp_path / "in", "b", WRONG)
    first = grader.grade(right, id="alice")
    session = grader._checks
    second = grader.grade(wrong, id="bob")
    third = grader.grade(right, id="alice")
    assert session is not None and grader._checks is session  # one session served all three
    assert first.outcome == third.outcome == "graded"
    assert verdicts(first) == verdicts(third)
    assert first.tests == third.tests
    assert [t.score for t in first.tests] == [2.0, 1.0, 1.0], verdicts(first)
    # B's own answers, never A's: B is wrong, and the state it sees is its own
    assert dict((t.name, t.score) for t in second.tests) == {
        "double": 0.0, "state_is_this_submissions_own": 0.0,
        "parameter_changed_in_place[pair]": 0.0}
    by_name = {t.name: t.output for t in second.tests}
    assert "state carried over" not in by_name["state_is_this_submissions_own"]
    assert by_name["parameter_changed_in_place[pair]"] == "values [1, 2, 3]"


def test_an_edited_check_or_helper_is_picked_up(stateful: tuple[Path, Grader],
                                                right: Path) -> None:
    folder, grader = stateful
    check = folder / "checks" / "public" / "test_double.py"
    try:
        before = grader.grade(right, id="alice")
        check.write_text(CHECKS + '\n\ndef test_added_later(student):\n'
                         '    assert student.double(2) == 5, "an edited check"\n')
        after = grader.grade(right, id="alice")
        (folder / "checks" / "public" / "stateful_helper.py").write_text("REMEMBERED = [0]\n")
        helper_edited = grader.grade(right, id="alice")
    finally:
        restored(folder)
    assert [t.name for t in before.tests] == [
        "double", "state_is_this_submissions_own", "parameter_changed_in_place[pair]"]
    assert [t.name for t in after.tests][-1] == "added_later"
    assert after.tests[-1].output == "an edited check"
    assert before.key != after.key
    # the helper's new list starts with 0: the state check now fails, showing it
    state = {t.name: t for t in helper_edited.tests}["state_is_this_submissions_own"]
    assert state.score == 0 and "[0, 42]" in state.output
    assert verdicts(grader.grade(right, id="alice")) == verdicts(before)


def test_a_broken_check_stops_grading_until_fixed(stateful: tuple[Path, Grader],
                                                  right: Path) -> None:
    folder, grader = stateful
    check = folder / "checks" / "public" / "test_double.py"
    try:
        good = grader.grade(right, id="alice")
        check.write_text(CHECKS + "\ndef test_broken(student:\n")
        with pytest.raises(AssignmentError, match="could not be collected"):
            grader.grade(right, id="alice")
        assert grader._checks is None
    finally:
        restored(folder)
    assert verdicts(grader.grade(right, id="alice")) == verdicts(good)


SKIPS_AN_ITEM = """
def pytest_runtest_protocol(item, nextitem):
    if item.name == "test_double":
        return True  # claims the item ran: no verdict is recorded for it
"""


@pytest.mark.parametrize("breaks, error", [
    ("conftest", EngineError),
    ("interrupt", KeyboardInterrupt),
])
def test_a_broken_run_is_an_error_and_the_next_gets_a_new_session(
        stateful: tuple[Path, Grader], right: Path, breaks: str,
        error: type[BaseException]) -> None:
    """Fewer verdicts than items is an EngineError, Ctrl-C in a check a KeyboardInterrupt;
    either way nothing is returned, and the next submission collects a new session."""
    folder, grader = stateful
    public = folder / "checks" / "public"
    good = grader.grade(right, id="alice")
    try:
        if breaks == "conftest":
            (public / "conftest.py").write_text(SKIPS_AN_ITEM)
        else:
            (public / "test_double.py").write_text(
                CHECKS + "\n\ndef test_pressed_ctrl_c():\n    raise KeyboardInterrupt\n")
        with pytest.raises(error):
            grader.grade(right, id="alice")
        assert grader._checks is None
    finally:
        (public / "conftest.py").unlink(missing_ok=True)
        restored(folder)
    assert verdicts(grader.grade(right, id="alice")) == verdicts(good)


def test_two_assignments_with_the_same_module_names_in_one_process(
        stateful: tuple[Path, Grader], right: Path, tmp_path: Path) -> None:
    """The service keeps a Grader per assignment in one process; their check modules share
    names (``checks.public.test_double``, ``stateful_helper``) and must never mix."""
    _, one = stateful
    other = write_assignment(tmp_path, "other", CHECKS.replace(
        "assert answer == 42", "assert answer == 43"))
    with Grader(load_assignment(other)) as two:
        results = [grader.grade(right, id="alice") for grader in (one, two, one, two)]
    assert verdicts(results[0]) == verdicts(results[2])
    assert verdicts(results[1]) == verdicts(results[3])
    assert results[0].tests[0].score == 2.0 and results[1].tests[0].score == 0.0


MARKED = '''
import warnings

import pytest


def _warn():
    warnings.warn("a numerical warning", RuntimeWarning)


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_warning_is_an_error(student):
    assert student.double(2) == 4
    _warn()


def test_warning_is_only_a_warning(student):
    _warn()
    assert student.double(2) == 4


@pytest.mark.skip(reason="not graded this term")
def test_skipped(student):
    assert student.double(2) == 4


@pytest.mark.skipif(True, reason="on this platform")
def test_skipped_if(student):
    assert student.double(2) == 4


@pytest.fixture
def broken_fixture():
    raise ValueError("the fixture broke")


def test_uses_broken_fixture(student, broken_fixture):
    assert student.double(2) == 4


def test_prints(student):
    print("a check's own output")
    assert student.double(2) == 4
'''


def test_marks_and_fixtures_act_as_in_pytest_s_own_protocol(tmp_path: Path) -> None:
    """Items run without pytest's reporting hooks (checkrun._run_item) and still honour
    the markers that change how a check runs: ``filterwarnings`` turns a warning into
    the check's failure (it stays a warning elsewhere), ``skip`` and ``skipif`` skip
    it, and a fixture that raises fails it at setup; twice over, in one session."""
    folder = write_double(tmp_path, "marked", {"test_marked.py": MARKED})
    right = submission(tmp_path / "in", "a", RIGHT)
    with Grader(load_assignment(folder)) as grader:
        runs = [grader.grade(right, id="alice") for _ in range(2)]
        assert grader._checks is not None and grader._checks._light  # the lighter path ran
    expected = {
        "warning_is_an_error": ("check-error", 0.0), "warning_is_only_a_warning": ("ok", 1.0),
        "skipped": ("check-error", 0.0), "skipped_if": ("check-error", 0.0),
        "uses_broken_fixture": ("check-error", 0.0), "prints": ("ok", 1.0)}
    for result in runs:
        assert {t.name: (t.kind, t.score) for t in result.tests} == expected, verdicts(result)
        by_name = {t.name: t.output for t in result.tests}
        assert by_name["skipped"] == by_name["skipped_if"] == \
            "This check was skipped by the grader."
    assert verdicts(runs[0]) == verdicts(runs[1])
