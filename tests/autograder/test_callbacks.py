"""Functions across the boundary: a check passes callables, the student returns them.

Every test here runs student code in a real sandboxed worker (one warm slot for
the module) and calls it through the ``student`` proxy, as checks do.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator

import numpy as np
import pytest

from autograder.engine import callbacks
from autograder.engine.callbacks import traced
from autograder.engine.proxy import Student, StudentFunction
from autograder.engine.slot import GradingSlot
from autograder.errors import CallTimeout, StudentException, UsageError
from tests.support.students import running

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the worker needs Linux (fork)")

NOTEBOOK = '''
import numpy as np

def apply(f, x):
    return f(x)

def apply_all(fs, x):
    return {name: [g(x) for g in group] for name, group in fs.items()}

def count_to(f, n):
    total = 0.0
    for i in range(n):
        total += f(float(i))
    return total

def forever(f):
    while True:
        try:
            f(1.0)
        except BaseException:
            pass

def swallow(f):
    for i in range(10**9):
        try:
            f(1.0)
        except Exception:
            pass

kept = []

def keep(f):
    kept.append(f)
    return len(kept)

def call_kept(x):
    return kept[-1](x)

def make_scaler(a):
    def scale(x):
        return a * np.asarray(x)
    return scale

def make_pair():
    return (lambda x: x + 1, {"g": lambda x: 2 * x})

def call_with(f, g):
    return f(g)

def describe(f):
    return [repr(f), [name for name in dir(f) if not name.startswith("_")]]

def sum_points(f, xs):
    return float(np.sum(f(np.asarray(xs))))
'''


@pytest.fixture(scope="module")
def slot() -> Iterator[GradingSlot]:
    with GradingSlot() as worker:
        yield worker


@pytest.fixture
def student(slot: GradingSlot) -> Iterator[Student]:
    with running(slot, NOTEBOOK, timeout=5) as proxy:
        yield proxy


def test_numpy_ufunc_hidden_lambda_and_list_of_functions(student: Student) -> None:
    assert student.apply(np.sin, 0.5) == np.sin(0.5)
    secret = 3.25
    hidden = traced(lambda x: secret * x ** 2)
    got = student.apply(hidden, np.arange(4.0))
    assert np.array_equal(got, secret * np.arange(4.0) ** 2)
    assert hidden.calls == 1 and np.array_equal(hidden.points, np.arange(4.0))
    both = student.apply_all({"first": [np.cos, hidden], "second": [abs]}, -2.0)
    assert both == {"first": [np.cos(-2.0), secret * 4.0], "second": [2.0]}
    assert hidden.calls == 2 and hidden.evaluations == 5
    assert hidden.records[-1].args == (-2.0,)


def test_the_function_code_never_enters_the_worker(student: Student) -> None:
    marker = 17.125

    def hidden_helper(x):
        return marker + x

    shown = student.describe(traced(hidden_helper, name="g"))
    assert shown == ["<function g given by the grader>", []]
    assert "hidden_helper" not in repr(shown) and "17.125" not in repr(shown)


def test_safe_functions_run_in_the_worker_and_are_still_counted(student: Student) -> None:
    f = traced(np.sin, safe=True)
    total = student.count_to(f, 1000)
    assert total == pytest.approx(np.sin(np.arange(1000.0)).sum())
    assert f.calls == 1000 and f.evaluations == 1000
    assert np.array_equal(f.points, np.arange(1000.0))
    # the counts' acknowledgement never gets in the way of the next calls
    assert student.apply(np.sqrt, 4.0) == 2.0 and student.apply(np.sqrt, 9.0) == 3.0
    with pytest.raises(UsageError, match="cannot be evaluated inside the worker"):
        traced(lambda x: x, safe=True)


def test_grader_side_callbacks_are_counted_one_by_one(student: Student) -> None:
    f = traced(np.exp)
    assert student.count_to(f, 200) == pytest.approx(np.exp(np.arange(200.0)).sum())
    assert f.calls == 200 and f.evaluations == 200


def test_too_many_callbacks_meet_a_clear_limit_and_the_grader_survives(
        student: Student, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(callbacks, "MAX_CALLBACKS", 50)
    f = traced(np.exp)
    with pytest.raises(StudentException, match="more than 50 times in one call"):
        student.count_to(f, 10**9)
    assert f.calls == 50
    with pytest.raises(StudentException, match="CallbackLimitExceeded"):  # not an Exception:
        student.call("swallow", f)                       # `except Exception` does not hide it
    assert student.apply(np.sqrt, 4.0) == 2.0  # the same worker answers the next call


def test_a_loop_that_swallows_the_limit_meets_the_cpu_limit(
        student: Student, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(callbacks, "MAX_CALLBACKS", 20)
    with pytest.raises(CallTimeout, match="CPU time"):
        student.call("forever", np.exp, timeout=0.5)
    assert student.apply(np.sqrt, 9.0) == 3.0  # restarted, and still grading


def test_garbage_arguments_raise_inside_the_students_code(student: Student) -> None:
    with pytest.raises(StudentException) as raised:
        student.apply(traced(lambda x: x * 2.0, name="f"), None)  # f(None) fails in the grader
    assert "f` raised TypeError when called with None" in str(raised.value)
    with pytest.raises(StudentException, match="accepts numbers and numpy arrays"):
        student.call_with(traced(np.exp), np.sin)  # exp(<stub>): functions cannot be passed back
    assert student.apply(np.exp, 0.0) == 1.0


def test_a_kept_function_is_stale_after_its_call(student: Student) -> None:
    f = traced(np.exp)
    assert student.keep(f) == 1
    with pytest.raises(StudentException, match="StaleCallback: `f` was given to your function "
                                               "for one call only"):
        student.call_kept(1.0)
    assert f.calls == 0


def test_a_returned_function_calls_into_the_worker(student: Student) -> None:
    scale = student.make_scaler(3.0)
    assert isinstance(scale, StudentFunction)
    assert scale(2.0) == 6.0
    assert np.array_equal(scale(np.arange(3)), [0.0, 3.0, 6.0])
    plus_one, table = student.make_pair()
    assert plus_one(1) == 2 and table["g"](4) == 8
    # handed back to the student, it runs there (no round trip through the grader)
    assert student.apply(scale, 5.0) == 15.0
    with pytest.raises(StudentException, match="TypeError"):
        scale("x", "y")


def test_a_check_function_cannot_call_the_student_while_it_waits(student: Student) -> None:
    def reentrant(x):
        return student.apply(np.exp, x)

    with pytest.raises(UsageError, match="cannot call the student's code"):
        student.apply(reentrant, 1.0)
    assert student.apply(np.exp, 0.0) == 1.0


def test_evaluation_points_of_vectorised_calls(student: Student) -> None:
    f = traced(np.cos)
    xs = np.linspace(-1, 1, 7)
    assert student.sum_points(f, xs) == pytest.approx(np.cos(xs).sum())
    assert f.calls == 1 and np.array_equal(f.points, xs)
    f.reset()
    assert f.calls == 0 and f.points.size == 0


def test_any_exception_of_the_checks_function_is_the_students_and_noted_for_the_instructor(
        student: Student) -> None:
    def buggy(x):
        return undefined_name * x  # type: ignore[name-defined]  # noqa: F821

    f = traced(buggy)
    # the student's arguments could have caused it: never the check's fault, never an engine
    # error; an unusual type may be the check's own bug, so the instructor's log says so
    with pytest.raises(StudentException, match="`f` raised NameError when called with 1.0"):
        student.apply(f, 1.0)
    assert student._log.notes and "NameError" in student._log.notes[-1]
    assert f.errors and f.errors[0].startswith("NameError")
    assert student.apply(np.exp, 0.0) == 1.0
