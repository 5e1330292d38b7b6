"""Files of the service: uploads stored by content hash, one result folder per grading."""

from __future__ import annotations

import hashlib
from pathlib import Path

from autograder.results.files import atomic_write_bytes


class Storage:
    """``root/uploads/<sha[:2]>/<sha>.ipynb`` (or ``.zip``) and ``root/results/<job>-<claim>/``."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def upload_path(self, sha256: str, suffix: str = "") -> Path:
        """The stored upload ``sha256``: the zip when one was stored under it (the engine
        tells a zip by its name), else the notebook."""
        folder = self.root / "uploads" / sha256[:2]
        if suffix:
            return folder / f"{sha256}{suffix}"
        zipped = folder / f"{sha256}.zip"
        return zipped if zipped.exists() else folder / f"{sha256}.ipynb"

    def store(self, data: bytes, *, suffix: str = ".ipynb") -> str:
        """Store ``data`` once under its SHA-256 (atomic; a second copy is a no-op)."""
        sha = hashlib.sha256(data).hexdigest()
        path = self.upload_path(sha, suffix)
        if path.exists():
            return sha
        atomic_write_bytes(path, data)
        return sha

    def result_dir(self, job_id: int, claim: str) -> Path:
        return self.root / "results" / f"{job_id}-{claim[:12]}"

    def resolve_result(self, relative: str) -> Path | None:
        """The folder of a recorded result, only if it lies inside ``root/results``."""
        base = (self.root / "results").resolve()
        path = (self.root / relative).resolve()
        return path if path.parent == base and path.is_dir() else None
