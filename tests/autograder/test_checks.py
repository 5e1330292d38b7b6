"""Tests of autograder.checks, the check-authoring module: comparisons (NaN, infinities,
shapes, kinds, staged messages), named datasets and their points, message text, pictures."""

from __future__ import annotations

import io

import numpy as np
import pytest

import autograder.checks as checks
from autograder.checks import (
    CheckFailure,
    Conventions,
    Credit,
    Dataset,
    call_for_figure,
    describe,
    expect_array,
    expect_close,
    expect_equal,
    expect_figure,
    expect_indices,
    expect_int,
    expect_number,
    explain_errors,
    figure_png,
    is_figure,
    over_datasets,
    plural,
    sentence,
    sentences,
    show_list,
    show_number,
    show_point,
    show_points,
    side_by_side,
)
from autograder.errors import PartialCredit, StudentException

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
INF, NAN = np.inf, np.nan


def failure(fn, *args, **kwargs) -> str:
    with pytest.raises(CheckFailure) as info:
        fn(*args, **kwargs)
    return str(info.value)


# ---------------------------------------------------------------------------
# the public surface
# ---------------------------------------------------------------------------

def test_every_public_name_is_exported_and_documented():
    for name in checks.__all__:
        obj = getattr(checks, name)
        assert obj.__doc__, f"autograder.checks.{name} has no docstring"
    assert {"Student", "Credit", "Feedback", "CheckFailure", "Dataset", "over_datasets",
            "show_number", "expect_close", "expect_array", "side_by_side"} <= set(checks.__all__)


def test_check_failure_is_in_compare_all():
    import autograder.checks.compare_arrays as compare

    assert "CheckFailure" in compare.__all__
    assert issubclass(CheckFailure, AssertionError)


# ---------------------------------------------------------------------------
# expect_close: non-finite values
# ---------------------------------------------------------------------------

@pytest.mark.parametrize(("got", "expected", "words"), [
    (5.0, NAN, "5 at index (scalar) where NaN was expected"),
    (NAN, 5.0, "NaN at index (scalar) where 5 was expected"),
    (-INF, INF, "-inf at index (scalar) where +inf was expected"),
    (INF, -INF, "+inf at index (scalar) where -inf was expected"),
    (1e308, INF, "1e+308 at index (scalar) where +inf was expected"),
    (INF, 1e308, "+inf at index (scalar) where 1e+308 was expected"),
    (NAN, INF, "NaN at index (scalar) where +inf was expected"),
])
def test_expect_close_refuses_wrong_non_finite_values(got, expected, words):
    assert words in failure(expect_close, got, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(("got", "expected"), [
    (NAN, NAN), (INF, INF), (-INF, -INF),
    ([1.0, NAN, -INF, INF], [1.0, NAN, -INF, INF]),
    (np.array([[NAN, 2.0], [3.0, INF]]), np.array([[NAN, 2.0], [3.0, INF]])),
])
def test_expect_close_accepts_matching_non_finite_values(got, expected):
    expect_close(got, expected, rtol=0, atol=0)


def test_expect_close_mixed_array_names_the_first_bad_index_and_the_count():
    got = np.array([[1.0, NAN, 3.0], [INF, 5.0, 6.0]])
    want = np.array([[1.0, 2.0, 3.0], [-INF, 5.0, 6.0]])
    message = failure(expect_close, got, want, rtol=1e-12, atol=0, name="f(x)")
    assert message.startswith("f(x) has NaN at index [0, 1] where 2 was expected")
    assert "2 of 6 values" in message


def test_expect_close_infinity_does_not_poison_the_finite_comparison():
    # inf - inf is nan: the finite entries must still be compared, and pass or fail alone
    expect_close([INF, 1.0], [INF, 1.0 + 1e-13], rtol=1e-12, atol=0)
    message = failure(expect_close, [INF, 1.1], [INF, 1.0], rtol=1e-12, atol=0)
    assert "off at index [1]: expected 1, got 1.1" in message


def test_expect_close_prints_every_digit_that_matters():
    message = failure(expect_close, 0.9999999, 1.0, rtol=1e-12, atol=0, name="factor")
    assert "expected 1, got 0.9999999" in message
    assert "1 of 1 value(s)" in message


def test_expect_close_complex_and_integer_inputs():
    expect_close(np.array([1 + 2j]), [1 + 2j], rtol=0, atol=0)
    expect_close([1, 2, 3], np.array([1.0, 2.0, 3.0]), rtol=0, atol=0)
    assert "off at index [0]" in failure(expect_close, [1 + 2j], [1 + 3j], rtol=1e-9, atol=0)


# ---------------------------------------------------------------------------
# expect_close: where, array tolerances, hints
# ---------------------------------------------------------------------------

def test_expect_close_at_names_the_place_of_the_worst_entry():
    t = np.array([0.0, 0.5, 1.0])
    message = failure(expect_close, [0.0, 0.7, 1.0 + 1e-9], [0.0, 0.5, 1.0], rtol=0, atol=1e-6,
                      name="p(t)", at=lambda i: f"t = {show_number(t[i])}")
    assert message == ("p(t) is off at t = 0.5: expected 0.5, got 0.7 (error 2.00e-01, allowed "
                       "1.00e-06); 1 of 3 value(s) are outside the tolerance.")


def test_expect_close_at_receives_the_full_index():
    seen = []

    def at(index):
        seen.append(index)
        return f"row {index[0]}, column {index[1]}"

    message = failure(expect_close, np.eye(2) * 2, np.eye(2), rtol=1e-9, atol=0, at=at)
    assert "is off at row 0, column 0: expected 1, got 2" in message
    assert seen == [(0, 0)]
    assert "at a scalar" in failure(expect_close, 2.0, 1.0, rtol=0, atol=0,
                                    at=lambda i: "a scalar" if i == () else "?")


@pytest.mark.parametrize(("got", "expected", "words"), [
    ([1.0, NAN], [1.0, 2.0], "has NaN at node 1 where 2 was expected"),
    ([1.0, -INF], [1.0, INF], "has -inf at node 1 where +inf was expected"),
    ([1.0, 5.0], [1.0, NAN], "has 5 at node 1 where NaN was expected"),
])
def test_expect_close_at_also_names_non_finite_places(got, expected, words):
    message = failure(expect_close, got, expected, rtol=0, atol=1, at=lambda i: f"node {i[0]}",
                      hint="Check the nodes.")
    assert words in message and message.endswith(". Check the nodes.")


def test_expect_close_array_atol_is_a_tolerance_per_entry():
    want = np.array([[1.0, 100.0], [2.0, 200.0]])
    per_column = np.array([1e-6, 1e-3])
    expect_close(want + [[5e-7, 5e-4], [-5e-7, -5e-4]], want, rtol=0, atol=per_column)
    message = failure(expect_close, want + [[0, 0], [2e-6, 5e-4]], want, rtol=0, atol=per_column)
    assert "off at index [1, 0]" in message and "allowed 1.00e-06" in message
    # the worst entry relative to its own bound is named, not the largest error
    message = failure(expect_close, want + [[0, 9e-4], [2e-6, 0]], want, rtol=0,
                      atol=per_column)
    assert "off at index [1, 0]" in message


def test_expect_close_array_rtol_and_infinite_expected_entries():
    expect_close([INF, 1.0 + 1e-10], [INF, 1.0], rtol=[0, 1e-9], atol=0)
    assert "off at index [1]" in failure(expect_close, [INF, 1.1], [INF, 1.0], rtol=[0, 1e-9],
                                         atol=0)


@pytest.mark.parametrize(("rtol", "atol", "words"), [
    (0, [1e-9, 1e-9, 1e-9], "`atol` must be a number or an array that broadcasts"),
    (0, -1e-9, "`atol` must be finite and >= 0"),
    (0, NAN, "`atol` must be finite and >= 0"),
    ([NAN, 0], 0, "`rtol` must be finite and >= 0"),
    ("big", 0, "`rtol` must be a number or an array"),
])
def test_expect_close_refuses_bad_tolerances(rtol, atol, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        expect_close([1.0, 2.0], [1.0, 2.0], rtol=rtol, atol=atol)


def test_expect_close_hint_ends_shape_and_value_failures():
    hint = "Return one value per t."
    assert failure(expect_close, [1.0], [1.0, 2.0], rtol=0, atol=0, hint=hint).endswith(hint)
    assert failure(expect_close, [1.0, 3.0], [1.0, 2.0], rtol=0, atol=0, hint=hint).endswith(
        "outside the tolerance. " + hint)
    expect_close([1.0, 2.0], [1.0, 2.0], rtol=0, atol=0, hint=hint)


# ---------------------------------------------------------------------------
# staging: type, then shape, then values
# ---------------------------------------------------------------------------

@pytest.mark.parametrize(("got", "words"), [
    (None, "did you forget `return`?"),
    ("1.0", "should be an array-like"),
    ({"a": 1}, "should be an array-like"),
    ([[1.0, 2.0], [3.0]], "rectangular"),
    (np.array(["a", "b"]), "should hold"),
])
def test_type_comes_before_shape_and_values(got, words):
    assert words in failure(expect_close, got, [1.0, 2.0], rtol=0, atol=0)


def test_expect_array_hint_ends_every_failure():
    hint = "Return the row numbers, like [2, 1, 4]."
    assert failure(expect_array, "abc", dtype_kind="iu", hint=hint).endswith(
        f"; got a str ('abc'). {hint}")
    assert failure(expect_array, [0.5], dtype_kind="iu", hint=hint).endswith(hint)
    assert failure(expect_array, [[1, 2]], shape=(None,), hint=hint).endswith(
        f"got shape (1, 2). {hint}")
    assert "Return" not in failure(expect_array, [[1, 2]], shape=(None,))


def test_shape_comes_before_values():
    message = failure(expect_close, [NAN, NAN, NAN], [1.0, 2.0], rtol=0, atol=0, name="y")
    assert message == "y should have shape (2); got shape (3,)."


@pytest.mark.parametrize(("shape", "got", "ok"), [
    ((None, 2), np.zeros((5, 2)), True),
    ((None, 2), np.zeros((5, 3)), False),
    ((3,), np.zeros(3), True),
    ((3,), np.zeros((3, 1)), False),
    ((), np.float64(1.0), True),
])
def test_expect_array_shapes(shape, got, ok):
    if ok:
        assert expect_array(got, shape=shape).shape == np.shape(got)
    else:
        assert "should have shape" in failure(expect_array, got, shape=shape)


@pytest.mark.parametrize(("kind", "got", "ok"), [
    ("iu", np.array([1, 2], dtype=np.int32), True),
    ("iu", np.array([1, 2], dtype=np.uint8), True),
    ("iu", np.array([1.0, 2.0]), False),
    ("f", np.array([1.0]), True),
    ("f", np.array([True]), False),
    ("b", np.array([True, False]), True),
    ("c", np.array([1j]), True),
    ("if", np.array([1j]), False),
])
def test_expect_array_dtype_kinds(kind, got, ok):
    if ok:
        expect_array(got, dtype_kind=kind)
    else:
        message = failure(expect_array, got, dtype_kind=kind, name="idx")
        assert message.startswith("idx should hold ")


def test_expect_int_and_equal():
    assert expect_int(np.int64(3)) == 3 and expect_int(np.array(4)) == 4 and expect_int(5.0) == 5
    assert "should be an integer" in failure(expect_int, True)
    assert "should be an integer; got 2.5" in failure(expect_int, 2.5)
    expect_equal(np.array([1, 2]), np.array([1, 2]))
    assert "differs at index [1]" in failure(expect_equal, np.array([1, 3]), np.array([1, 2]))
    assert "expected True" in failure(expect_equal, 1, True)


@pytest.mark.parametrize(("got", "value"), [
    (0.5, 0.5), (3, 3.0), (np.float32(0.25), 0.25), (np.int64(7), 7.0), (np.array(1.5), 1.5),
    (NAN, NAN), (-INF, -INF),
])
def test_expect_number_accepts_real_scalars(got, value):
    result = expect_number(got)
    assert type(result) is float and (result == value or (np.isnan(value) and np.isnan(result)))


@pytest.mark.parametrize(("got", "words"), [
    (True, "a bool"), (None, "None"), ("0.5", "a str"), (np.array([0.5]), "shape (1,)"),
    (np.zeros((2, 2)), "shape (2, 2)"), ([0.5], "a list of 1"), (1j, "a complex"),
    (np.array(True), "dtype bool"),
])
def test_expect_number_refuses_everything_else(got, words):
    message = failure(expect_number, got, name="p(0.3)", hint="Return float(...).")
    assert message.startswith("p(0.3) should be a single number; got ")
    assert words in message and message.endswith(". Return float(...).")


def test_expect_figure_returns_figure_data_or_says_what_came_back():
    figure = {"axes": [], "png": b""}
    assert expect_figure(figure, name="plot(x)") is figure
    assert failure(expect_figure, None, name="plot(x)") == (
        "plot(x) should return the matplotlib Figure it drew on (fig, ax = plt.subplots(); "
        "...; return fig); got None (did you forget `return`?).")
    assert failure(expect_figure, [1], name="plot(x)", hint="no figure was drawn either"
                   ).endswith("got a list of 1 item(s). No figure was drawn either.")


def test_expect_indices_are_rows_of_the_table():
    got = expect_indices([2, 0, 1], 3, shape=(None,))
    assert got.dtype == np.int64 and got.tolist() == [2, 0, 1]
    assert failure(expect_indices, [2, 3, -1], 3, name="hull") == (
        "hull holds 3 at entry [1], which is not a row of `points`: it has 3 rows, so "
        "indices run from 0 to 2.")
    tri = np.array([[0, 1, 2], [1, -1, 2]])
    message = failure(expect_indices, tri, 3, shape=(None, 3), name="delaunay(points)",
                      at=lambda i: f"triangle {i[0]} {show_point(tri[i[0]])}", hint="Subtract 1?")
    assert message == ("delaunay(points) holds -1 at triangle 1 (1, -1, 2), which is not a row "
                       "of `points`: it has 3 rows, so indices run from 0 to 2. Subtract 1?")
    assert "it has no rows" in failure(expect_indices, [0], 0, rows="`nodes`")


@pytest.mark.parametrize(("got", "words"), [
    ([0.0, 1.0], "should hold integers"), ([[0, 1]], "should have shape (any)"),
    ("01", "should be an array-like of integers"),
])
def test_expect_indices_stages_before_the_range(got, words):
    assert words in failure(expect_indices, got, 5, shape=(None,), hint="Row numbers, please.")


def test_describe_is_short_and_safe():
    assert describe(None).startswith("None")
    assert describe(np.zeros((3, 2))) == "an array of shape (3, 2) and dtype float64"
    assert len(describe("x" * 1000)) < 100


# ---------------------------------------------------------------------------
# datasets and their points
# ---------------------------------------------------------------------------

def test_dataset_requires_a_reason_for_its_tolerance():
    with pytest.raises(ValueError, match="needs a `reason`"):
        Dataset(lambda rng: 1, tolerance=1e-9)
    with pytest.raises(ValueError, match="`points`"):
        Dataset(lambda rng: 1, points=-1)
    with pytest.raises(TypeError, match="`build`"):
        Dataset([1, 2, 3])  # type: ignore[arg-type]
    data = Dataset(lambda rng: rng.uniform(size=3), points=2, tolerance=1e-9,
                   reason="three numbers: rounding only")
    assert data.build(np.random.default_rng(0)).shape == (3,)
    with pytest.raises(AttributeError):
        data.points = 3  # type: ignore[misc]  # frozen


def test_dataset_tol_is_the_tolerance_or_an_error():
    assert Dataset(lambda rng: 1, tolerance=1e-9, reason="rounding").tol == 1e-9
    assert isinstance(Dataset(lambda rng: 1, tolerance=0, reason="exact").tol, float)
    with pytest.raises(TypeError, match="no `tolerance`"):
        Dataset(lambda rng: 1).tol


@pytest.mark.filterwarnings("ignore::pytest.PytestUnknownMarkWarning")
def test_over_datasets_parametrises_with_ids_and_points():
    datasets = {"small": Dataset(lambda rng: 1), "unseen-big": Dataset(lambda rng: 2, points=3)}
    mark = over_datasets(datasets)
    argname, params = mark.args
    assert argname == "name"
    assert [p.id for p in params] == ["small", "unseen-big"]
    assert [p.values for p in params] == [("small",), ("unseen-big",)]
    assert [p.marks[0].args for p in params] == [(1.0,), (3.0,)]
    assert [p.marks[0].name for p in params] == ["points", "points"]
    override = over_datasets(datasets, "case", points=lambda d: d.points * 2)
    assert override.args[0] == "case" and override.args[1][1].marks[0].args == (6.0,)
    with pytest.raises(ValueError):
        over_datasets({})


@pytest.mark.filterwarnings("ignore::pytest.PytestUnknownMarkWarning")
def test_over_datasets_decorates_a_check():
    @over_datasets({"a": Dataset(lambda rng: 1, points=2)}, "case")
    def check(case):
        return case

    (mark,) = check.pytestmark
    assert mark.name == "parametrize" and mark.args[0] == "case"
    assert mark.args[1][0].marks[0].args == (2.0,)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnknownMarkWarning")
def test_over_datasets_runs_over_some_datasets_in_the_given_order():
    datasets = {"a": Dataset(lambda rng: 1, points=2), "b": Dataset(lambda rng: 2),
                "c": Dataset(lambda rng: 3, points=3)}
    argname, params = over_datasets(datasets, only=["c", "a"], points=1).args
    assert [p.id for p in params] == ["c", "a"]
    assert [p.marks[0].args for p in params] == [(1.0,), (1.0,)]
    assert [p.marks[0].args for p in over_datasets(datasets, only=["c"]).args[1]] == [(3.0,)]
    with pytest.raises(ValueError, match="`only` must name datasets"):
        over_datasets(datasets, only=["a", "unseen"])
    with pytest.raises(ValueError, match="`only`"):
        over_datasets(datasets, only=[])


# ---------------------------------------------------------------------------
# partial credit for broken conventions
# ---------------------------------------------------------------------------

def partial(fn, *args, **kwargs) -> PartialCredit:
    with pytest.raises(PartialCredit) as info:
        fn(*args, **kwargs)
    return info.value


def test_broken_conventions_multiply_and_keep_the_first_message():
    conventions = Conventions({"clockwise": 0.5, "closed": 0.75})
    broken = conventions.record()
    broken.finish(Credit())  # nothing broken: full points, the check goes on
    broken.note("clockwise", "your hull is right but clockwise")
    broken.note("clockwise", "a second message about the same convention")
    broken.note("closed", "list each corner once.")
    assert len(broken) == 2 and broken.fraction == 0.375
    ended = partial(broken.finish, Credit())
    assert ended.fraction == 0.375
    assert str(ended) == "Your hull is right but clockwise. List each corner once."
    broken.note("closed", "convex_hull(points) repeats its first corner", replace=True)
    assert broken.message().endswith(" convex_hull(points) repeats its first corner.")
    assert conventions.record().fraction == 1  # a fresh record per check


def test_conventions_refuse_bad_fractions_and_unknown_keys():
    for bad in (0, 1, 1.5, -0.5, True, "half"):
        with pytest.raises(ValueError, match="strictly between 0 and 1"):
            Conventions({"clockwise": bad})  # type: ignore[dict-item]
    conventions = Conventions({"clockwise": 0.5})
    with pytest.raises(KeyError, match="'one-based' is not a convention"):
        conventions.record().note("one-based", "indices start at 0")
    with pytest.raises(TypeError):
        conventions.fractions["clockwise"] = 1.0  # type: ignore[index]  # read-only
    ended = partial(conventions.partial, Credit(), "clockwise", "triangle 0 is clockwise")
    assert (ended.fraction, str(ended)) == (0.5, "Triangle 0 is clockwise.")


# ---------------------------------------------------------------------------
# calling the student
# ---------------------------------------------------------------------------

def raise_student(exc_type: str, detail: str) -> None:
    raise StudentException(f"weights raised {exc_type}: {detail}", traceback="Traceback: line 3",
                           function="weights", exc_type=exc_type, detail=detail)


def test_explain_errors_explains_known_exception_types_only():
    hints = {"OverflowError": "Divide by the largest binomial first."}
    with pytest.raises(CheckFailure) as info:
        with explain_errors("weights(1100)", hints):
            raise_student("OverflowError", "int too large to convert to float")
    assert str(info.value) == ("weights(1100) raised OverflowError: int too large to convert "
                               "to float. Divide by the largest binomial first.")
    with pytest.raises(CheckFailure, match="Traceback: line 3"):
        with explain_errors("weights(1100)", hints, traceback=True):
            raise_student("OverflowError", "int too large")
    with pytest.raises(StudentException):  # another type: reported by the plugin as it is
        with explain_errors("weights(1100)", hints):
            raise_student("ValueError", "bad n")
    with explain_errors("weights(3)", hints):
        pass  # no exception, nothing to explain


class Plotting:
    """A stand-in for the ``student`` fixture: ``call`` returns what it was given."""

    def __init__(self, value: object, opened: list[object]) -> None:
        self.value, self.opened = value, opened

    def call(self, name: str, *args: object, figures: bool = False) -> tuple[object, list]:
        assert figures
        return self.value, self.opened


def test_call_for_figure_finds_the_returned_or_the_last_drawn_figure():
    png = _png()
    returned, drawn = {"axes": [], "png": png}, {"axes": [{"lines": []}]}
    images = []

    class Attach:
        def image(self, label: str, data: bytes) -> None:
            images.append((label, data))

    value, figure = call_for_figure(Plotting(returned, [drawn]), "plot", 3, feedback=Attach())
    assert value is returned and figure is returned and images == [("your plot", png)]
    value, figure = call_for_figure(Plotting(None, [returned, drawn, "junk"]), "plot")
    assert value is None and figure is drawn
    assert call_for_figure(Plotting("ax", []), "plot", label="x", feedback=Attach()) == ("ax", None)
    assert len(images) == 1  # no picture, nothing attached
    assert is_figure(drawn) and not is_figure({"axes": "none"}) and not is_figure(None)


# ---------------------------------------------------------------------------
# text
# ---------------------------------------------------------------------------

@pytest.mark.parametrize(("value", "text"), [
    (0.9999999, "0.9999999"), (1.0, "1"), (-3.0, "-3"), (0.1, "0.1"), (1e-300, "1e-300"),
    (2.0**60, "1.152921504606847e+18"), (np.float32(0.5), "0.5"), (np.int64(7), "7"),
    (NAN, "nan"), (INF, "inf"), (-INF, "-inf"), (True, "1"),
])
def test_show_number_never_hides_a_difference(value, text):
    assert show_number(value) == text


def test_show_number_with_digits_never_rounds_to_an_integer_it_is_not():
    assert show_number(0.9999999, digits=4) == "0.9999999"
    assert show_number(2.00000001, digits=3) == "2.00000001"
    assert show_number(3.14159265, digits=3) == "3.14"
    assert show_number(5.0, digits=3) == "5"


def test_points_lists_and_sentences():
    assert show_point((0.1, 2.0)) == "(0.1, 2)"
    assert show_point(np.array([1.5, -2.25, 3.0])) == "(1.5, -2.25, 3)"
    assert show_list(range(10), limit=3) == "[0, 1, 2, ... (7 more)]"
    assert show_list([0.5, 1.0]) == "[0.5, 1]"
    assert plural(1, "point") == "1 point" and plural(2.5, "point") == "2.5 points"
    assert show_points(1.5, 2) == "1.5 of 2 points"
    assert sentence("the hull is wrong") == "The hull is wrong."
    assert sentence("convex_hull(points) returned 3.") == "convex_hull(points) returned 3."
    assert sentence("") == ""
    assert sentences(["the hull is wrong", "", "plot_runge(3) returned None"]) == (
        "The hull is wrong. plot_runge(3) returned None.")


# ---------------------------------------------------------------------------
# pictures
# ---------------------------------------------------------------------------

def _png() -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2))
    FigureCanvasAgg(fig)
    fig.add_subplot().plot([0, 1], [1, 0])
    return checks.render_png(fig, dpi=30)


def test_figure_png_reads_figure_data():
    png = _png()
    assert png.startswith(PNG_SIGNATURE)
    assert figure_png({"axes": [], "png": png}) == png
    assert figure_png({"axes": [], "png": np.frombuffer(png, dtype=np.uint8)}) == png
    assert figure_png({"axes": [], "png": b"GIF89a"}) is None
    assert figure_png(None) is None and figure_png({"axes": []}) is None


@pytest.mark.parametrize("student", [None, b"junk", "figure"])
def test_side_by_side_draws_the_given_reference(student):
    import matplotlib.image as mpimg

    drawn = []
    value = {"axes": [], "png": _png()} if student == "figure" else student
    png = side_by_side(value, lambda ax: drawn.append(ax.plot([0, 1], [0, 1])),
                       right_title="the reference car")
    assert png.startswith(PNG_SIGNATURE) and len(drawn) == 1
    assert mpimg.imread(io.BytesIO(png), format="png").shape[:2] == (320, 800)
