"""Hidden test cells never reach the student: not before they run, not through feedback.

A course's hidden test cell (nbgrader's ``### BEGIN HIDDEN TESTS``) runs in the
student's process. These students hunt for it: walking frames up from their own
cell and through ``gc`` before any test ran, reading it once the test has run and
printing it, raising it, returning it to a check, and speaking the grader's
protocol themselves to be sent it early. The secret must appear nowhere in the
result folder; honest students keep their scores.
"""

from __future__ import annotations

import uuid
from dataclasses import replace
from pathlib import Path

import nbformat
import pytest

from autograder.engine.assignment import load_assignment
from autograder.engine.celltests import WITHHELD, CellTest
from autograder.engine.grader import Grader
from tests.support.assignments import CHECK, write_double

#: what the students look for; the hidden test holds it followed by a part they cannot know
PREFIX = "numgrade-" + "secret-"  # split: the student's own source must not match

HUNT = '''
def _hunt():
    """Every string in reach holding the secret's prefix (frames up, then gc)."""
    import gc, sys
    prefix = "numgrade-" + "secret-"
    found = set()
    def look(value, depth):
        if depth > 6:
            return
        if isinstance(value, str):
            if prefix in value and value != prefix:
                found.add(value[value.index(prefix):][:60])
        elif isinstance(value, dict):
            for item in list(value.values())[:5000]:
                look(item, depth + 1)
        elif isinstance(value, (list, tuple, set, frozenset)):
            for item in list(value)[:5000]:
                look(item, depth + 1)
    frame = sys._getframe()
    while frame is not None:
        look(dict(frame.f_locals), 0)
        frame = frame.f_back
    for obj in gc.get_objects():
        look(obj, 5)
    return sorted(found)
'''

#: prints what it found before any test ran; its ``double`` raises whatever it finds later
HUNTER = HUNT + '''
print("BEFORE ANY TEST:", _hunt())

def double(x):
    found = _hunt()
    if found:
        raise ValueError("CAUGHT " + " ".join(found))
    return 2 * x
'''

LAST = 'print("AFTER THE TESTS:", _hunt())\nraise RuntimeError("CAUGHT " + " ".join(_hunt()))\n'

#: speaks the grader's protocol from its own cell: announces the hidden cell (index 1),
#: asks for its source, and swaps the worker's own announcement and request for
#: ones that keep quiet, so the grader sees the protocol followed
CONNECTION = '''
def _connection():
    """The worker's socket and module, from the worker's "announce this cell" lambda."""
    import gc, socket
    announce = next(f for f in gc.get_objects()
                    if type(f).__name__ == "function" and f.__name__ == "<lambda>"
                    and f.__code__.co_filename.endswith("__main__.py") and f.__closure__)
    sock = next(c.cell_contents for c in announce.__closure__
                if isinstance(c.cell_contents, socket.socket))
    return sock, announce.__globals__
'''

FORGER = HUNT + CONNECTION + '''
import sys
frames = sys.modules["autograder.boundary.frames"]
sock, worker = _connection()
frames.send_message(sock, {"op": "cell", "index": 1})
frames.send_message(sock, {"op": "need-source", "index": 1, "cells": [], "stdout": ""})
try:
    stolen = frames.recv_message(sock, timeout=5)
except Exception as exc:  # the grader did not answer: look around instead
    stolen = {"source": "", "hunt": _hunt()}
print("STOLEN:", stolen)
worker["_hidden_source"] = lambda sock, index, run, output: stolen["source"]
real_announce, said = worker["_announce"], []
def _announce(sock, index):  # cell 1 was announced above already
    if index == 1 and not said:
        said.append(index)
        return
    real_announce(sock, index)
worker["_announce"] = _announce

def double(x):
    return 2 * x if stolen["source"] else -1  # right only once the source was stolen
'''


def _meta(grade_id: str, *, test: bool) -> dict:
    return {"nbgrader": {"grade_id": grade_id, "grade": test, "solution": not test,
                         "locked": test, "schema_version": 3}}


def _student(path: Path, cells: list[tuple[str, str | None]]) -> Path:
    """A notebook of code cells ``(source, grade_id)``; grade_ids ``test_*`` are test cells."""
    book = nbformat.v4.new_notebook()
    for source, grade_id in cells:
        meta = _meta(grade_id, test=grade_id.startswith("test")) if grade_id else {}
        book.cells.append(nbformat.v4.new_code_cell(source, metadata=meta))
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(book, path)
    return path


@pytest.fixture
def course(tmp_path: Path):
    """An nbgrader-style assignment: a pytest check, then a hidden and a visible test cell."""
    secret = PREFIX + uuid.uuid4().hex
    folder = write_double(tmp_path, "dbl", {"test_double.py": CHECK})
    tests = (CellTest("test_hidden", "dbl.ipynb", 3.0,
                      f"# {secret}\nprint({secret!r})\nassert double(3) == 6, {secret!r}\n",
                      hidden=True, grade_id="test_hidden"),
             CellTest("test_after", "dbl.ipynb", 2.0,
                      "assert double(2) == 4, 'double(2) should be 4'\n", grade_id="test_after"))
    return replace(load_assignment(folder), cell_tests=tests), secret


def _grade(assignment, path: Path, out: Path):
    with Grader(assignment) as grader:
        return grader.grade(path, id="s", out_dir=out)


def _leaks(out: Path, secret: str) -> list[str]:
    tail = secret[len(PREFIX):]
    return [str(p.relative_to(out)) for p in out.rglob("*") if p.is_file()
            and (tail.encode() in p.read_bytes())]


def _released(hunter: str) -> list[tuple[str, str | None]]:
    return [(hunter, "double"), ("# hidden tests run here\n", "test_hidden"),
            ("assert double(2) == 4\n", "test_after"), (LAST, "last")]


def test_a_student_hunting_the_hidden_test_finds_nothing_to_show(tmp_path: Path, course) -> None:
    assignment, secret = course
    out = tmp_path / "out" / "s"
    result = _grade(assignment, _student(tmp_path / "s.ipynb", _released(HUNTER)), out)
    assert _leaks(out, secret) == []
    assert secret[len(PREFIX):] not in result.stdout + result.output
    # before the hidden test the process held nothing of it
    assert "BEFORE ANY TEST: []" in result.stdout
    assert "AFTER THE TESTS" not in result.stdout  # printed after a hidden test: held back
    assert WITHHELD in result.notes
    after = next(t for t in result.tests if t.name == "test_after")
    assert after.score == 0.0 and after.output == WITHHELD
    check = next(t for t in result.tests if t.name == "double")
    assert check.score == 0.0 and check.output == WITHHELD  # double(21) raised the secret
    hidden = next(t for t in result.tests if t.name == "test_hidden")
    assert hidden.output == "Hidden test failed."
    assert [e.ename for e in result.cell_errors] == ["Error"]  # the last cell, its text cut


def test_a_student_asking_for_the_hidden_source_shows_nothing_of_it(tmp_path: Path,
                                                                    course) -> None:
    assignment, secret = course
    out = tmp_path / "out" / "s"
    result = _grade(assignment, _student(tmp_path / "s.ipynb", _released(FORGER)), out)
    assert _leaks(out, secret) == []
    assert "STOLEN" not in result.stdout  # the answer came: what followed is not shown
    assert WITHHELD in result.notes
    assert [e.cell for e in result.cell_errors] == [3]  # the forger's cell ran to its end
    # the grader answered the forged request (the worker's own turn never came): the
    # attack got the source, and still nothing of it reached the feedback
    assert {t.name: t.score for t in result.tests} == {
        "test_hidden": 3.0, "test_after": 2.0, "double": 1.0}


def test_a_request_for_a_cell_the_worker_has_not_reached_is_refused(tmp_path: Path,
                                                                    course) -> None:
    assignment, secret = course
    asks = FORGER.replace('frames.send_message(sock, {"op": "cell", "index": 1})\n', "")
    out = tmp_path / "out" / "s"
    result = _grade(assignment, _student(tmp_path / "s.ipynb", _released(asks)), out)
    assert _leaks(out, secret) == []
    # the cell that spoke for the worker is stopped and skipped; the rest ran without it
    assert "Cell 1 stopped the worker" in result.output
    assert "asked for the source of cell 2" in result.output  # counted from 1, as shown
    assert {t.name: t.score for t in result.tests if t.name.startswith("test")} == {
        "test_hidden": 0.0, "test_after": 0.0}  # no `double` without the skipped cell


def test_an_honest_student_keeps_every_point_and_the_output_before_the_hidden_test(
        tmp_path: Path, course) -> None:
    assignment, secret = course
    path = _student(tmp_path / "s.ipynb", [
        ("def double(x):\n    return 2 * x\nprint('shown before the tests')\n", "double"),
        ("# hidden tests run here\n", "test_hidden"), ("assert double(2) == 4\n", "test_after"),
        ("print('printed at the end')\n", "last")])
    out = tmp_path / "out" / "s"
    result = _grade(assignment, path, out)
    assert {t.name: t.score for t in result.tests} == {
        "test_hidden": 3.0, "test_after": 2.0, "double": 1.0}
    assert result.score == result.max_score == 6.0
    assert "shown before the tests" in result.stdout
    assert "printed at the end" not in result.stdout
    assert _leaks(out, secret) == []


#: after the hidden test: writes what it found to the grader's connection, as a frame
#: the grader's protocol-violation message would quote
SPEAKER = CONNECTION + HUNTER.replace("def double(x):", """def _say(found):
    import sys
    frames = sys.modules["autograder.boundary.frames"]
    sock, _ = _connection()
    tail = found[0][len("numgrade-" + "secret-"):] if found else "nothing"
    frames.send_message(sock, {"op": tail[:30], "index": tail[:30]})

def double(x):""")


def test_a_frame_sent_after_the_hidden_test_is_not_quoted(tmp_path: Path, course) -> None:
    assignment, secret = course
    out = tmp_path / "out" / "s"
    path = _student(tmp_path / "s.ipynb", [
        (SPEAKER, "double"), ("# hidden tests run here\n", "test_hidden"),
        ("_say(_hunt())\n", "last")])
    result = _grade(assignment, path, out)
    assert _leaks(out, secret[:len(PREFIX) + 30]) == []
    assert "broke the grader's protocol" in result.output
    assert "not shown: a hidden test had run" in result.output
