"""The error bad batch input raises: an input that names no sequence, a manifest CSV with a bad header or row."""
from __future__ import annotations

from pathlib import Path

from vslam.errors import VslamError


class BatchError(VslamError):
    """Bad input to `vslam batch`; names the file and, where it applies, the line (1-based) and the field."""

    def __init__(self, path: str | Path | None, problem: str, line: int | None = None, field: str | None = None):
        self.path = Path(path) if path is not None else None
        self.line = line
        self.field = field
        self.problem = problem
        where = "" if path is None else str(self.path) + (f":{line}" if line is not None else "") + ": "
        what = f"field '{field}': " if field else ""
        super().__init__(f"{where}{what}{problem}")
