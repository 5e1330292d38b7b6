"""Files of the service: uploads stored by content hash, one result folder per grading."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path


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
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".upload-")
        try:
            with os.fdopen(fd, "wb") as handle:
                handle.write(data)
                handle.flush()
                os.fsync(handle.fileno())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return sha

    def result_dir(self, job_id: int, claim: str) -> Path:
        return self.root / "results" / f"{job_id}-{claim[:12]}"

    def resolve_result(self, relative: str) -> Path | None:
        """The folder of a recorded result, only if it lies inside ``root/results``."""
        base = (self.root / "results").resolve()
        path = (self.root / relative).resolve()
        return path if path.parent == base and path.is_dir() else None
