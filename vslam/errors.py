"""The root of the errors `vslam` raises on bad input, and the typed errors of sequence reading.

Every one derives from `VslamError` (itself an `odometry.shared.errors.ToolkitError`, so a `ValueError`) and
names the file and, where it applies, the line (1-based) and the field; the CLI reports them on one line.
"""
from __future__ import annotations

from pathlib import Path

from odometry.shared.errors import ToolkitError


class VslamError(ToolkitError):
    """Bad input to the composition layer: a sequence, a run directory, a command's arguments."""


class SequenceError(VslamError):
    """A sequence that cannot be read as given."""

    def __init__(self, path: str | Path, problem: str, line: int | None = None, field: str | None = None):
        self.path = Path(path)
        self.line = line
        self.field = field
        self.problem = problem
        where = str(self.path) + (f":{line}" if line is not None else "")
        what = f"field '{field}': " if field else ""
        super().__init__(f"{where}: {what}{problem}")


class MissingFileError(SequenceError):
    """A file the sequence needs is absent."""


class CalibrationError(SequenceError):
    """camera.yaml is missing a field or holds a bad value."""


class CsvFormatError(SequenceError):
    """A CSV stream has a bad header, a short row or a non-numeric value."""


class UnknownColumnError(CsvFormatError):
    """A CSV header names a column the schema does not have."""


class NonFiniteValueError(CsvFormatError):
    """A NaN or infinite number where a measurement is expected."""


class TimestampOrderError(SequenceError):
    """Timestamps that do not strictly increase."""


class ImageReadError(SequenceError):
    """An image file that is missing, unreadable or corrupt."""


class EmptySequenceError(SequenceError):
    """A sequence with no frames."""


class SkippedInputWarning(UserWarning):
    """Input skipped with the run going on (an unreadable frame, a key image without features, an evaluation that
    cannot be computed); the message names the file."""
