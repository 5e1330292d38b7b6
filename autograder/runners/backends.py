"""Where gradings run: the local process pool, or a Dask cluster.

A backend takes the submissions still to grade and calls ``finished`` once per
submission with its :class:`~autograder.results.model.SubmissionResult`, after the
result's files are in ``out_dir/<id>/``. Everything else (ids, reuse by key,
the progress bar, ``grades.csv``, the summary, the exports) is the batch's, so
both backends give the same folder.

``distributed`` is imported only by :mod:`autograder.runners.dask_cluster`,
which is imported only when a :class:`DaskSpec` is used.
"""

from __future__ import annotations

from types import ModuleType

from autograder.engine.slot import GradingSlot
from autograder.errors import UsageError
from autograder.runners.jobs import Backend, DaskSpec


def load_dask_backend() -> ModuleType:
    """:mod:`autograder.runners.dask_cluster`, or a clear error when ``distributed`` is missing."""
    try:
        from autograder.runners import dask_cluster
    except ImportError as exc:
        raise UsageError(f"Grading on Dask needs the `dask` extra ({exc}); install it with "
                         "pip install \"numgrade[dask]\".") from None
    return dask_cluster


def make_backend(*, jobs: int | None = None, dask: DaskSpec | None = None,
                 started_slot: GradingSlot | None = None) -> Backend:
    """The local pool, or the Dask backend when ``dask`` is given (imports ``distributed``).

    ``started_slot``, a slot started ahead, becomes the local pool's slot 0.
    """
    if dask is not None:
        return load_dask_backend().DaskBackend(dask)
    from autograder.runners.local import LocalBackend

    return LocalBackend(jobs, started_slot=started_slot)


__all__ = ["load_dask_backend", "make_backend"]
