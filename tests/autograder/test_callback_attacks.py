"""Attacks through functions across the boundary and through figure data, each with its defence.

* the grader's memory: a student calls a check's function again and again with a
  large array (recorded arguments are kept within a byte budget);
* uncounted calls: ``f(x=t)``, ``f(*[t])``, a returned object's method (every call's
  points are counted, whatever the spelling);
* exceptions: arguments that make recording or the check's function raise (always
  the student's error, never the check's or the engine's);
* returned functions: errors with huge or forged messages and tracebacks (the same
  caps as an ordinary call);
* figures: forged figure data, returned or sent by a patched worker (validated and
  cut on the grader's side).

End to end (a hidden check's data in feedback.html and results.json, and the
result's size) see ``test_returned_function_attacks_end_to_end`` below.
"""

from __future__ import annotations

import gc
import json
import sys
import tracemalloc
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from autograder.boundary.figurelimits import (
    MAX_FIGURE_POINTS,
    MAX_FIGURE_TEXT,
    MAX_NOTES,
    MAX_PNG_PIXELS,
    MAX_TEXT_CHARS,
)
from autograder.engine import callbacks
from autograder.engine.callbacks import ArgumentSummary, traced
from autograder.engine.figuredata import receive_figure, receive_value
from autograder.engine.proxy import Student
from autograder.engine.slot import GradingSlot
from autograder.errors import StudentException, WorkerCrashed
from tests.support.assignments import submission, write_double
from tests.support.students import running

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="the worker needs Linux (fork)")

#: a fake PNG: signature and IHDR of 100,000 x 100,000 pixels, nothing after
HUGE_PNG = (b"\x89PNG\r\n\x1a\n" + (13).to_bytes(4, "big") + b"IHDR"
            + (100_000).to_bytes(4, "big") * 2 + b"\x08\x06\x00\x00\x00")

NOTEBOOK = '''
import gc
import os
import sys

import numpy as np

def flood(f, n, size, keyword):
    x = np.ones(size)
    for _ in range(n):
        if keyword:
            f(x=x)
        else:
            f(x)
    return n

def by_keyword(f, t):
    return f(x=np.asarray(t))

def by_star(f, t):
    return f(*[np.asarray(t)])

def spread(f, t):
    return f(*t)

def huge_int(f):
    return f(10**400)

def apply(f, x):
    return f(x)

class Model:
    def fit(self, f, t):
        return f(x=np.asarray(t))

    def __call__(self, f, t):
        return f(*[np.asarray(t)])

def make_model():
    return Model()

def make_method():
    return Model().fit

def make_loud():
    def p(t):
        raise ValueError("L" * 1_000_000)
    return p

def _forge(answer):
    channel = next(o for o in gc.get_objects() if type(o).__name__ == "Channel")
    sys.modules["autograder.boundary.frames"].send_message(channel.sock, answer)
    os._exit(0)

def make_forger():
    def p(t):
        _forge({"ok": False, "error": "exception", "type": "ValueError" * 50,
                "message": "M" * 900_000, "traceback": "T" * 900_000, "stdout": ""})
    return p

def make_odd_error():
    def p(t):
        _forge({"ok": False, "error": "E" * 900_000, "stdout": ""})
    return p

def forged_figure():
    big = np.arange(1_000_000, dtype=float)
    line = {"x": big, "y": big, "label": "L" * 900_000, "color": "#000000",
            "linestyle": "-", "marker": ""}
    axes = {"lines": [line] * 3 + ["not a line"], "collections": [], "patches": [],
            "images": [{"shape": [1, 2, 3, 4], "extent": [0, 1, 0, 1]}],
            "texts": ["T" * 900_000] * 4, "xlim": [0.0, 1.0], "ylim": "wide",
            "xlabel": "x", "ylabel": "y", "title": "t", "aspect": "auto", "legend": []}
    return {"$t": "figure", "axes": [axes], "suptitle": "S" * 900_000, "png": HUGE_PNG,
            "truncated": False, "notes": ["n"] * 1000}

def patch_figures():
    forged = forged_figure()
    small = np.arange(300_000, dtype=float)
    forged["axes"][0]["lines"] = [dict(forged["axes"][0]["lines"][0], x=small, y=small)]
    blank = {"$t": "figure", "axes": [], "suptitle": "", "png": b"", "truncated": False,
             "notes": []}
    sys.modules["autograder.worker.figures"].figures_data = lambda **k: [forged] + [blank] * 99
    return 1
'''.replace("HUGE_PNG", repr(HUGE_PNG))


@pytest.fixture(scope="module")
def slot() -> Iterator[GradingSlot]:
    with GradingSlot() as worker:
        yield worker


@pytest.fixture
def student(slot: GradingSlot) -> Iterator[Student]:
    with running(slot, NOTEBOOK, timeout=20) as proxy:
        yield proxy


# -- 1. the grader's memory ----------------------------------------------------------
@pytest.mark.parametrize("keyword", [False, True], ids=["positional", "keyword"])
def test_recorded_arguments_stay_within_a_byte_budget(student: Student, keyword: bool) -> None:
    """40 calls with an 8 MB array: 320 MB kept before; now at most the points (16 MB),
    the records' budget (4 MB) and summaries. Bound: 40 MB kept after the call, 100 MB at
    the peak (a few 8 MB messages in flight), as tracemalloc counts the grader's memory;
    without a collection of reference cycles in between (the decoder was one)."""
    f = traced(lambda x: 0.0)
    tracemalloc.start()
    gc.disable()
    try:
        base = tracemalloc.get_traced_memory()[0]
        assert student.flood(f, 40, 1_000_000, keyword) == 40
        kept, peak = tracemalloc.get_traced_memory()
    finally:
        gc.enable()
        tracemalloc.stop()
    assert kept - base < 40 * 2**20, f"the grader kept {(kept - base) / 2**20:.0f} MB"
    assert peak - base < 100 * 2**20, f"the grader peaked at {(peak - base) / 2**20:.0f} MB"
    assert f.calls == 40 and f.evaluations == 40_000_000 and f.truncated
    assert f.points.size == callbacks.MAX_RECORDED_POINTS
    record = f.records[-1]
    assert not record.complete
    summary = record.kwargs["x"] if keyword else record.args[0]
    assert summary == ArgumentSummary("ndarray", (1_000_000,), "<f8", (1.0,) * 8)


def test_small_arguments_are_kept_whole(student: Student) -> None:
    f = traced(lambda x: x)
    student.by_keyword(f, [0.5, 0.25])
    assert f.records[0].complete and np.array_equal(f.records[0].kwargs["x"], [0.5, 0.25])


# -- 2. every call counted, whatever its spelling -----------------------------------
def test_every_spelling_of_a_call_is_counted(student: Student) -> None:
    t = [0.1, 0.2, 0.3]
    for name in ("by_keyword", "by_star"):
        f = traced(lambda x: x)
        student.call(name, f, t)
        assert (f.calls, f.evaluations) == (1, 3), name
        assert np.array_equal(f.points, t), name
    variadic = traced(lambda *xs: sum(xs))
    assert student.spread(variadic, t) == pytest.approx(0.6)
    assert variadic.evaluations == 3 and np.array_equal(variadic.points, t)
    # methods and callable objects the student returned, given a check's function
    for made in (student.make_method(), student.make_model()):
        g = traced(lambda x: x)
        made(g, t)
        assert g.evaluations == 3 and np.array_equal(g.points, t), made


# -- 3. exceptions on the student's arguments ---------------------------------------
def test_arguments_that_break_recording_are_not_the_checks_fault(student: Student) -> None:
    f = traced(lambda x: 1.0)
    assert student.huge_int(f) == 1.0  # recording 10**400 as a point raised OverflowError
    assert f.calls == 1 and f.evaluations == 1
    with pytest.raises(StudentException, match=r"`f` raised AttributeError when called with "
                                               r"a list of length 2"):
        student.apply(traced(lambda x: x.shape), [1.0, 2.0])
    with pytest.raises(StudentException, match="raised OverflowError"):
        student.apply(traced(lambda x: float(x)), 10**400)
    assert student.apply(np.exp, 0.0) == 1.0


# -- 4. returned functions: the same caps as ordinary calls --------------------------
def test_a_returned_functions_error_meets_the_caps(student: Student) -> None:
    p = student.make_loud()
    with pytest.raises(StudentException) as raised:
        p(1.0)
    exc = raised.value
    assert exc.function == "the function returned by make_loud()" and exc.exc_type == "ValueError"
    assert len(exc.detail) <= 2000 and len(str(exc)) < 2200 and len(exc.traceback) <= 20_000


def test_a_forged_answer_of_a_returned_function_meets_the_caps(student: Student) -> None:
    with pytest.raises(StudentException) as raised:
        student.make_forger()(1.0)
    exc = raised.value
    assert len(exc.exc_type) <= 100 and len(exc.detail) <= 2000
    assert len(str(exc)) < 2300 and len(exc.traceback) <= 20_000
    with pytest.raises(WorkerCrashed) as crashed:
        student.make_odd_error()(1.0)
    assert len(str(crashed.value)) < 300


# -- 5. figures, validated on the grader's side ------------------------------------
def _assert_within_budget(figure: dict) -> None:
    points = sum(line["x"].size for ax in figure["axes"] for line in ax["lines"])
    assert points <= MAX_FIGURE_POINTS and figure["truncated"]
    texts = [figure["suptitle"]] + [t for ax in figure["axes"] for t in ax["texts"]] + [
        line["label"] for ax in figure["axes"] for line in ax["lines"]]
    assert all(len(t) <= MAX_TEXT_CHARS for t in texts) and sum(map(len, texts)) <= MAX_FIGURE_TEXT
    assert figure["png"] == b"" and len(figure["notes"]) <= MAX_NOTES
    assert any("picture was dropped" in n and f"{MAX_PNG_PIXELS:,}" in n for n in figure["notes"])


def test_a_forged_returned_figure_is_cut_to_the_budget(student: Student) -> None:
    figure = student.forged_figure()
    _assert_within_budget(figure)
    ax = figure["axes"][0]
    assert len(ax["lines"]) == 3 and ax["images"] == [] and ax["ylim"] != "wide"
    assert any("lines 3 was dropped" in n for n in figure["notes"])


def test_figures_sent_by_a_patched_worker_are_cut_to_the_budget(student: Student) -> None:
    assert student.patch_figures() == 1
    _, opened = student.call("apply", np.exp, 0.0, figures=True)
    assert len(opened) == 50
    _assert_within_budget(opened[0])
    assert len(student.figures()) == 50


def test_honest_figure_data_passes_unchanged() -> None:
    from autograder.worker import figures  # selects Agg before pyplot is imported
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    try:
        ax.plot([0, 1, 2], [1, 0, 1], "r--", label="curve")
        ax.scatter([0.5], [0.5])
        ax.set_title("honest")
        data = figures.figure_to_data(fig)
    finally:
        plt.close(fig)
    got = receive_figure(data)
    assert got["notes"] == data["notes"] and not got["truncated"] and got["png"] == data["png"]
    assert np.array_equal(got["axes"][0]["lines"][0]["y"], [1, 0, 1])
    assert got["axes"][0]["title"] == "honest" and got["axes"][0]["lines"][0]["label"] == "curve"
    assert np.array_equal(got["axes"][0]["collections"][0]["offsets"], [[0.5, 0.5]])


def test_garbage_in_place_of_a_figure() -> None:
    assert receive_figure("x")["axes"] == []
    assert receive_figure({"$t": "figure", "axes": [7], "png": 3})["notes"] == [
        "axes 0 was dropped: a int, not axes data", "picture was dropped: a int, not PNG bytes"]


def test_figures_deep_inside_a_returned_value_are_validated_too() -> None:
    forged = {"$t": "figure", "axes": [], "png": HUGE_PNG, "suptitle": "S" * 10**6}
    points = [(0.0, 1.0)] * 1000
    value = {"plots": [(1, [forged])], "points": points}
    got = receive_value(value)
    figure = got["plots"][0][1][0]
    assert figure["png"] == b"" and len(figure["suptitle"]) == MAX_TEXT_CHARS
    assert got["points"] is points  # containers without figures are not copied
    assert receive_value(points) is points


# -- end to end: hidden data and result sizes ----------------------------------------
SECRETS = [round(0.1 + k * 0.0137777, 7) for k in range(63)]

HIDDEN_CHECK = f'''
import numpy as np
import pytest

SECRET = np.array({SECRETS!r})

@pytest.mark.points(63)
def test_unseen_points(student):
    p = student.make()
    values = p(SECRET)
    assert np.allclose(values, 2 * SECRET), "p(t) must be 2 t"
'''

PUBLIC_CHECK = '''
import numpy as np

def test_seen_points(student):
    p = student.make()
    assert np.allclose(p(np.array([1.0, 2.0])), [2.0, 4.0]), "p(t) must be 2 t"
'''

LEAKY = '''
import numpy as np

def make():
    def leaky_inner_marker(t):
        raise ValueError("your points: " + repr(list(np.asarray(t))) * 5)
    return leaky_inner_marker
'''

FORGER = '''
import gc
import os
import sys

import numpy as np

def make():
    def p(t):
        loop = sys.modules["autograder.worker.loop"]
        found = gc.get_objects()
        channel = next(o for o in found if isinstance(o, loop.Channel))
        shell = next(o for o in found if isinstance(o, loop.GradingShell))
        output = next(o for o in found if isinstance(o, loop.BoundedText))
        message = repr(list(np.asarray(t)))
        loop.frames.send_message(channel.sock, {
            "ok": False, "error": "exception", "type": "ValueError",
            "message": (message + "M" * 900_000)[:990_000],
            "traceback": (message + "leaky_inner_marker" + "T" * 900_000)[:990_000],
            "stdout": ""})
        loop.serve(channel.sock, shell, output)  # answer the grader's next requests, in step
        os._exit(0)
    return p
'''


def test_returned_function_attacks_end_to_end(tmp_path: Path) -> None:
    """A hidden check's 63 points never reach feedback.html or results.json beyond the
    80-character excerpt hidden checks allow (at most 4 of them), no traceback of a hidden
    check is shown, and each result file stays under 200 kB however much the worker sent."""
    from autograder import api

    folder = write_double(tmp_path, "leak", {"test_public.py": PUBLIC_CHECK})
    (folder / "checks" / "hidden" / "test_hidden.py").write_text(HIDDEN_CHECK)
    submissions = tmp_path / "submissions"
    submission(submissions, "leaky", LEAKY)
    submission(submissions, "forger", FORGER)
    api.grade(folder, [submissions], out=tmp_path / "out", jobs=1, progress=False)
    for stem in ("leaky", "forger"):
        result_folder = tmp_path / "out" / stem
        result = json.loads((result_folder / "results.json").read_text())
        hidden = next(t for t in result["tests"] if t["name"] == "unseen_points")
        assert hidden["score"] == 0 and "on this hidden input" in hidden["output"], hidden
        assert "leaky_inner_marker" not in hidden["output"]
        for name in ("results.json", "feedback.html"):
            text = (result_folder / name).read_text()
            assert len(text.encode()) < 200_000, f"{stem}/{name}: {len(text.encode()):,} bytes"
            shown = [s for s in SECRETS if repr(s) in text]
            assert len(shown) <= 4, f"{stem}/{name} shows {len(shown)} of the 63 hidden points"
