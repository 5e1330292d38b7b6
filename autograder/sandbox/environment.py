"""The worker child's environment: built afresh, and the inherited one wiped.

Nothing is copied from the grader's environment (no tokens, no CI variables), and
the strings the process was started with are overwritten, so that not even
``/proc/self/environ`` shows them.
"""

from __future__ import annotations

import ctypes
import os
import tempfile
from pathlib import Path

from autograder.sandbox import kernel

__all__ = ["clean_environment", "replace_environment"]

SAFE_PATH = "/usr/local/bin:/usr/bin:/bin"


def clean_environment(workdir: Path) -> dict[str, str]:
    """Build the child's whole environment and create its temporary directory.

    Parameters
    ----------
    workdir : Path
        The submission's working directory; it becomes ``HOME``.

    Returns
    -------
    dict of str to str
        A fresh environment: nothing is copied from the grader's.
    """
    workdir = Path(workdir)
    tmpdir = workdir / ".tmp"
    tmpdir.mkdir(parents=True, exist_ok=True)
    return {
        "PATH": SAFE_PATH,
        "HOME": str(workdir),
        "TMPDIR": str(tmpdir),
        "LANG": "C.UTF-8",
        "LC_ALL": "C.UTF-8",
        "MPLBACKEND": "Agg",
        "MPLCONFIGDIR": str(workdir / ".mpl"),
        "OPENBLAS_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "PYTHONDONTWRITEBYTECODE": "1",
        "PYTHONHASHSEED": "0",
    }


def replace_environment(env: dict[str, str]) -> str:
    """Install ``env`` as the only environment, and wipe the inherited one.

    ``os.environ.clear()`` unsets the variables, but the strings the process was
    started with stay in its memory and are still listed by ``/proc/self/environ``;
    after ``clearenv()`` nothing refers to them, so they are overwritten with zeros.
    :mod:`tempfile` caches its directory, possibly already in the warm parent, so
    it is pointed at the new ``TMPDIR`` as well.
    """
    os.environ.clear()
    kernel.libc().clearenv()
    try:
        _zero_initial_environ()
    except (OSError, ValueError, IndexError) as exc:
        note = f"environment replaced; inherited block not wiped: {exc}"
    else:
        note = "environment replaced, inherited block wiped"
    os.environ.update(env)
    tempfile.tempdir = env["TMPDIR"]
    return note


def _zero_initial_environ() -> None:
    """Overwrite the block shown by ``/proc/self/environ`` (fields 50-51 of stat)."""
    stat = Path("/proc/self/stat").read_text()
    fields = stat.rsplit(")", 1)[1].split()  # fields[0] is field 3 ("state")
    start, end = int(fields[50 - 3]), int(fields[51 - 3])
    if not 0 < start < end:
        raise ValueError("/proc/self/stat hides the environment's addresses")
    ctypes.memset(start, 0, end - start)
