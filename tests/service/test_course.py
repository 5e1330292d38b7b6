"""The course file and the deadline arithmetic, and the optional reverse-proxy sign-in."""

from __future__ import annotations

import datetime as dt
from pathlib import Path

import pytest

from autograder.errors import UploadRejected, UsageError
from autograder.service.course import load_course
from autograder.service.intake import check_notebook

NOTEBOOKS = Path(__file__).resolve().parents[1] / "files" / "notebooks"

BASE = """
[course]
name = "C"
[[assignment]]
name = "hull"
opens = 2026-01-01T00:00:00Z
deadline = 2026-02-01T12:00:00+01:00
late_penalty_per_day = 0.1
max_late_days = 3
[assignment.extensions]
alice = 2026-02-03T12:00:00Z
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "course.toml"
    path.write_text(text)
    return path


def test_course_file_and_late_days(tmp_path: Path) -> None:
    course = load_course(write(tmp_path, BASE))
    hull = course.assignments[0]
    assert hull.deadline == dt.datetime(2026, 2, 1, 11, 0)  # naive UTC
    assert course.database_url.startswith("sqlite:///") and course.data_dir == tmp_path / "course-data"
    assert hull.deadline_for("alice") == dt.datetime(2026, 2, 3, 12, 0)
    assert hull.deadline_for("alice", dt.datetime(2026, 3, 1)) == dt.datetime(2026, 3, 1)
    assert hull.late_days(hull.deadline, hull.deadline) == 0
    assert hull.late_days(hull.deadline + dt.timedelta(seconds=1), hull.deadline) == 1
    assert hull.late_days(hull.deadline + dt.timedelta(days=1, seconds=1), hull.deadline) == 2
    assert hull.penalty(2) == pytest.approx(0.2)
    assert hull.closes_for(hull.deadline) == hull.deadline + dt.timedelta(days=3)


@pytest.mark.parametrize("change, words", [
    (("late_penalty_per_day = 0.1", "late_penalty_per_day = 10"), "fraction in [0, 1]"),
    (("max_late_days = 3", "max_late_days = -1"), "max_late_days"),
    (("name = \"hull\"", "name = \"hull\"\ncount = \"first\""), "\"best\" or \"last\""),
    (("deadline = 2026-02-01T12:00:00+01:00", "deadline = 2025-01-01T00:00:00Z"), "after opens"),
    (("[course]", "[course]\nsubmissions_per_hour = 0"), "submissions_per_hour"),
    (("[course]", "[course]\ncolour = 1"), "unknown key(s) ['colour']"),
    (("opens = 2026-01-01T00:00:00Z", "opens = \"soon\""), "date-time"),
])
def test_bad_course_files_say_what_and_where(tmp_path: Path, change: tuple[str, str], words: str) -> None:
    path = write(tmp_path, BASE.replace(*change))
    with pytest.raises(UsageError, match=None) as info:
        load_course(path)
    assert words in str(info.value) and str(path) in str(info.value)


def test_trusted_header_only_when_configured_and_from_the_proxy(tmp_path: Path) -> None:
    pytest.importorskip("fastapi")
    from fastapi.testclient import TestClient

    from autograder.service import auth
    from autograder.service.app import create_app
    from autograder.service.db import make_engine, sessions, upgrade

    text = BASE.replace("[course]", "[course]\n") + "\n[auth]\ntrusted_header = \"X-Remote-User\"\n" \
        "trusted_proxies = [\"testclient\"]\n"
    course = load_course(write(tmp_path, text))
    engine = make_engine(course.database_url)
    upgrade(engine)
    upgrade(engine)  # a second run is a no-op
    factory = sessions(engine)
    with factory.begin() as session:
        auth.import_roster(session, [auth.RosterEntry("alice", "Alice", "a@x", "student")])
    with TestClient(create_app(course, factory), follow_redirects=False) as client:
        assert client.get("/assignments", headers={"X-Remote-User": "alice"}).status_code == 200
        assert client.get("/assignments", headers={"X-Remote-User": "mallory"}).status_code == 303
        assert client.get("/assignments").status_code == 303
    other = load_course(write(tmp_path, text.replace('["testclient"]', '["10.0.0.1"]')))
    with TestClient(create_app(other, factory), follow_redirects=False) as client:
        assert client.get("/assignments", headers={"X-Remote-User": "alice"}).status_code == 303
    engine.dispose()


def test_an_upload_is_checked_in_memory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Checking an upload writes nothing: a server stopped meanwhile leaves no file behind."""
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)  # gettempdir() reads TMPDIR again
    check_notebook((NOTEBOOKS / "magics.ipynb").read_bytes(), 10**6)
    with pytest.raises(UploadRejected) as info:
        check_notebook((NOTEBOOKS / "not-json.ipynb").read_bytes(), 10**6)
    assert info.value.status == 422 and "not a notebook the grader can read" in str(info.value)
    with pytest.raises(UploadRejected) as too_big:
        check_notebook((NOTEBOOKS / "magics.ipynb").read_bytes(), 10)
    assert too_big.value.status == 413
    assert list(tmp_path.iterdir()) == []
