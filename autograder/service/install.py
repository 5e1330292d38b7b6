"""The student's install: the wheel a student installs with one ``pip`` line, served here.

``GET /install`` says the command; ``GET /install/numgrade-<version>-py3-none-any.whl``
is the wheel (pip needs the real wheel name in the URL: it reads name and version
from it). The wheel is built on the first request from the checkout the service runs
from, copied to a private folder first (so setuptools' ``build/`` never lingers in
the checkout with files of an older tree), and holds the ``autograder`` package only
(``pyproject.toml`` finds ``autograder*``): no ``reference/`` solutions, no
``assignments/`` and so no hidden check. Before it is served, its member list is
checked for those, and a wheel that holds one is refused. Its dependencies are
numgrade's own (the base install), never the ``service`` extra.
"""

from __future__ import annotations

import html
import shutil
import subprocess
import sys
import tempfile
import threading
import zipfile
from pathlib import Path

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse
from starlette.concurrency import run_in_threadpool

import autograder
from autograder.service.web import ServiceState

router = APIRouter()

#: the checkout holding numgrade's pyproject.toml, when the service runs from one
SOURCE = Path(autograder.__file__).resolve().parents[1]
WHEEL = f"numgrade-{autograder.__version__}-py3-none-any.whl"
#: what a student's wheel never holds (top-level folders and any path part)
FORBIDDEN_TOP = ("reference/", "assignments/", "tests/", "benchmarks/")
FORBIDDEN_PART = "hidden"
_LOCK = threading.Lock()


def forbidden_members(wheel: Path) -> list[str]:
    """Members of ``wheel`` a student must never get (solutions, assignments, hidden checks)."""
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
    return [n for n in names if n.startswith(FORBIDDEN_TOP) or FORBIDDEN_PART in n.split("/")]


class BuildInProgress(RuntimeError):
    """Another request is building the wheel right now."""


def build_student_wheel(out_dir: Path, source: Path = SOURCE) -> Path:
    """``out_dir/WHEEL``, built once from ``source`` (then reused until the version changes)."""
    target = out_dir / WHEEL
    if target.is_file():
        return target
    # Never wait on a build in progress: a request (anyone may ask for the wheel) that
    # waited would hold a worker thread, and enough of them would stall the service.
    if not _LOCK.acquire(blocking=False):
        raise BuildInProgress("the student package is being built; try again in a minute")
    try:
        if target.is_file():
            return target
        if not (source / "pyproject.toml").is_file():
            raise FileNotFoundError(f"the service runs from an install without numgrade's "
                                    f"pyproject.toml ({source}); put {WHEEL} in {out_dir}")
        out_dir.mkdir(parents=True, exist_ok=True, mode=0o700)
        with tempfile.TemporaryDirectory(prefix="numgrade-wheel-") as scratch:
            tree = Path(scratch) / "src"
            tree.mkdir()
            for name in ("pyproject.toml", "README.md", "LICENSE"):
                if (source / name).is_file():
                    shutil.copy2(source / name, tree / name)
            shutil.copytree(source / "autograder", tree / "autograder",
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            # pip's build isolation: setuptools as pyproject.toml asks, from the index
            subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                            "-w", str(Path(scratch) / "dist"), str(tree)],
                           check=True, capture_output=True, timeout=600)
            built = Path(scratch) / "dist" / WHEEL
            leaked = forbidden_members(built)
            if leaked:  # never served: the packaging would hand out what students must not see
                raise RuntimeError(f"the student wheel would hold {leaked[:5]}; fix pyproject.toml")
            shutil.move(str(built), target)
    finally:
        _LOCK.release()
    return target


def install_command(base_url: str) -> str:
    """The one line a student runs."""
    return f'python -m pip install "{base_url.rstrip("/")}/install/{WHEEL}"'


@router.get("/install", response_class=HTMLResponse)
async def install_page(request: Request) -> HTMLResponse:
    command = html.escape(install_command(str(request.base_url)))
    return HTMLResponse(
        "<!doctype html><html lang=en><meta charset=utf-8><title>Install numgrade</title>"
        "<h1>Install numgrade to check and submit your notebooks</h1>"
        f"<p>In a terminal (Python 3.11 or newer):</p><pre><code>{command}</code></pre>"
        f'<p>The package: <a href="install/{WHEEL}">{WHEEL}</a>. It holds the public '
        "grader only; see the course's instructions for <code>autograder check</code> and "
        "<code>autograder submit</code>.</p></html>")


@router.get("/install/{filename}")
async def student_wheel(filename: str, service: ServiceState) -> FileResponse:
    if filename != WHEEL:
        raise HTTPException(404, f"No such file; the package is /install/{WHEEL}.")
    try:
        wheel = await run_in_threadpool(build_student_wheel, service.course.data_dir / "install")
    except BuildInProgress as exc:
        raise HTTPException(503, f"{exc}.", headers={"Retry-After": "60"}) from None
    except (FileNotFoundError, RuntimeError, subprocess.SubprocessError) as exc:
        raise HTTPException(503, f"The student package cannot be built here: {exc}.") from None
    return FileResponse(wheel, media_type="application/octet-stream", filename=WHEEL)
