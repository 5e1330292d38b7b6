"""The student version of an instructor notebook, by nbgrader's own passes, kept on disk.

:mod:`autograder.engine.identify` compares a submission with the released
template (to tell an untouched template, and answers left as released). The
template is what nbgrader's ``ClearSolutions``, ``ClearHiddenTests`` and
``ClearMarkScheme`` make of the instructor notebook, the same passes as
``autograder release``. Importing nbgrader costs about 0.85 s (its package imports
its Jupyter server extensions), the largest single part of a batch's time to its
first result, and the passes' output depends only on the notebook's bytes and
nbgrader's version. So the output is kept in the user's cache folder
(``NUMGRADE_CACHE_DIR``, by default the platform's, ``~/.cache/numgrade`` on
Linux), under a name made of the SHA-256 of both: a changed notebook or another
nbgrader finds no entry and runs the passes again, so an entry is never stale.

The cache only saves time: an entry that cannot be read or written is computed
again, silently. What it holds is the released notebook, which students get
anyway; it is read and written only by the grader's own (trusted) process.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import logging
import os
from pathlib import Path
from typing import Any

import nbformat

from autograder.results.files import atomic_write_text

__all__ = ["cache_folder", "released_notebook"]

_LOG = logging.getLogger("autograder.engine.released")
#: bumped when the passes run here change, so older entries are not used
_FORMAT = "1"
_PASSES = ("ClearSolutions", "ClearHiddenTests", "ClearMarkScheme")


def cache_folder() -> Path:
    """Where released templates are kept: ``NUMGRADE_CACHE_DIR`` or the platform's cache."""
    chosen = os.environ.get("NUMGRADE_CACHE_DIR")
    if chosen:
        return Path(chosen) / "released"
    import platformdirs  # only when the variable is not set

    return Path(platformdirs.user_cache_dir("numgrade")) / "released"


def released_notebook(path: Path) -> Any:
    """The student version of the instructor notebook ``path``; None without nbgrader.

    None also when the notebook cannot be read or nbgrader rejects it (a warning
    is logged; ``autograder release`` reports the same problem to the instructor).
    """
    try:
        version = importlib.metadata.version("nbgrader")
    except importlib.metadata.PackageNotFoundError:
        return None
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        _LOG.warning("could not read %s for its released template: %s", path, exc)
        return None
    key = hashlib.sha256(b"\0".join([_FORMAT.encode(), version.encode(), data])).hexdigest()
    entry = cache_folder() / f"{key}.ipynb"
    try:
        return nbformat.reads(entry.read_text(encoding="utf-8"), as_version=4)
    except (OSError, ValueError):  # no entry yet (or a damaged one): run the passes
        pass
    try:
        released = _run_passes(nbformat.reads(data.decode("utf-8"), as_version=4))
    except (UnicodeDecodeError, ValueError) as exc:
        _LOG.warning("could not read %s for its released template: %s", path, exc)
        return None
    if released is not None:
        try:
            entry.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(entry, nbformat.writes(released))
        except OSError as exc:  # a read-only home: the next run computes it again
            _LOG.debug("could not keep the released template in %s: %s", entry.parent, exc)
    return released


def _run_passes(nb: Any) -> Any:
    try:
        from nbgrader import preprocessors  # about 0.85 s: see the module notes
    except ImportError:  # installed but broken: no template, as without nbgrader
        return None

    resources: dict[str, Any] = {}
    try:
        for name in _PASSES:
            nb, resources = getattr(preprocessors, name)(log=_LOG).preprocess(nb, resources)
    except Exception as exc:  # nbgrader rejects the notebook: release says so; here, no template
        _LOG.warning("nbgrader could not clear the instructor notebook: %s", exc)
        return None
    return nb
