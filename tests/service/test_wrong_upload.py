"""Another assignment's notebook uploaded to hull: refused with whose notebook it is, nothing stored."""

from __future__ import annotations

import httpx
import pytest
import svc_support as support
from conftest import Running
from sqlalchemy import text
from test_flows import sign_in

CAR = (support.ROOT / "assignments" / "spline_car" / "examples" / "solution.ipynb").read_bytes()
WORDS = "this is the spline_car notebook, not hull"


def stored(service: Running) -> tuple[int, int]:
    """(submissions in the database, files in the upload store)."""
    with service.engine.connect() as db:
        count = db.execute(text("SELECT count(*) FROM submissions")).scalar_one()
    uploads = service.data / "uploads"
    return count, sum(1 for p in uploads.rglob("*") if p.is_file()) if uploads.exists() else 0


def test_the_car_notebook_is_refused_over_http(service: Running) -> None:
    before = stored(service)
    with httpx.Client(timeout=60) as client:
        answer = support.upload(client, service.url, service.tokens["carol"], "hull", CAR)
    assert answer.status_code == 422, answer.text
    assert WORDS in answer.json()["error"].lower() and "Nothing was stored" in answer.json()["error"]
    assert stored(service) == before


@pytest.mark.browser
def test_the_car_notebook_is_refused_in_the_browser(service: Running, browser: support.WebDriver,
                                                     tmp_path) -> None:
    before = stored(service)
    sign_in(browser, service.url, service.tokens["carol"])
    browser.open(f"{service.url}/assignments/hull")
    notebook = tmp_path / "hull.ipynb"  # named as hull's: the cells say whose it is
    notebook.write_bytes(CAR)
    browser.type("#notebook", str(notebook))
    browser.click("#submit")
    browser.wait_for("return document.getElementById('upload-error') !== null", timeout=60)
    assert WORDS in browser.text("#upload-error").lower()
    assert stored(service) == before


def _zip(members: dict[str, bytes]) -> bytes:
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return buffer.getvalue()


HULL_PARTIAL = (support.HULL_EXAMPLES / "partial-only-orientation.ipynb").read_bytes()


@pytest.mark.parametrize("members, words", [
    ({"README.md": b"my work"}, "no notebook (.ipynb) was found in this zip"),
    ({"hw/hull.ipynb": CAR}, WORDS),
    ({"hull.ipynb": HULL_PARTIAL, "big.bin": bytes(20 * 1024 * 1024)}, "unpacks to 21.0 mb"),
    ({"hull.ipynb": HULL_PARTIAL, **{f"part{k}.bin": bytes(600_000) for k in range(4)}},
     "unpacks to"),
], ids=["no-notebook", "another-assignment", "zip-bomb", "many-small-parts"])
def test_a_zip_that_cannot_be_graded_is_refused(service: Running, members: dict[str, bytes],
                                                words: str) -> None:
    before = stored(service)
    with httpx.Client(timeout=60) as client:
        answer = support.upload(client, service.url, service.tokens["carol"], "hull",
                                _zip(members), name="submission.zip")
    assert answer.status_code == 422, answer.text
    assert words in answer.json()["error"].lower() and "Nothing was stored" in answer.json()["error"]
    assert stored(service) == before


def test_a_zip_holding_the_notebook_is_graded_as_the_notebook(service: Running) -> None:
    with httpx.Client(timeout=60) as client:
        # named by the browser as it likes: the grader tells a zip by its bytes
        answer = support.upload(client, service.url, service.tokens["carol"], "hull",
                                _zip({"work/hull.ipynb": HULL_PARTIAL, "work/notes.txt": b"x"}),
                                name="upload")
        assert answer.status_code == 201, answer.text
        view = support.wait_graded(client, service.url, service.tokens["carol"], answer.json()["id"])
    assert view["status"] == "graded", view
    assert 0 < view["raw_score"] < view["max_score"]
    with service.engine.connect() as db:
        name = db.execute(text("SELECT filename FROM submissions WHERE id = :i"),
                          {"i": answer.json()["id"]}).scalar_one()
    assert name == "upload.zip"
