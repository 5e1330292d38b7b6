"""Files of the service: uploads stored by content hash, one result folder per grading."""

from __future__ import annotations

import hashlib
from pathlib import Path

from autograder.results.files import atomic_write_bytes


class Storage:
    """``root/uploads/<sha[:2]>/<sha>.ipynb`` and ``root/results/<job>-<claim>/``."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def upload_path(self, sha256: str) -> Path:
        return self.root / "uploads" / sha256[:2] / f"{sha256}.ipynb"

    def store(self, data: bytes) -> str:
        """Store ``data`` once under its SHA-256 (atomic; a second copy is a no-op)."""
        sha = hashlib.sha256(data).hexdigest()
        path = self.upload_path(sha)
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
