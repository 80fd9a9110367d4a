"""Frames that cannot be read, noted as the run goes on (`--skip-bad-frames`).

By default a sequence whose frames.csv lists a missing image is refused when it is opened (strict). With
`skip_bad_frames` it is opened without that check; every frame that then fails to read (missing, truncated, corrupt)
is a failed frame for the command (VO falls back, loop detection skips it), warned about once with the file named,
and listed in the command's outputs.
"""
from __future__ import annotations

import warnings

import numpy as np

from vslam.errors import SkippedInputWarning
from vslam.sequence import Sequence


class NotedImages:
    """An image source that notes (and warns about) the frames it cannot read, then re-raises."""

    def __init__(self, inner):
        self.inner = inner
        self.problems: dict[int, str] = {}

    def __len__(self) -> int:
        return len(self.inner)

    def name(self, index: int) -> str:
        return self.inner.name(index)

    def read(self, index: int, gray: bool = False) -> np.ndarray:
        try:
            return self.inner.read(index, gray=gray)
        except (OSError, ValueError) as exc:    # ImageReadError is a ValueError
            if index not in self.problems:
                self.problems[index] = str(exc)
                warnings.warn(SkippedInputWarning(f"frame {index} skipped: {exc}"), stacklevel=2)
            raise

    def __getattr__(self, attr):   # path(), relpaths, root of the wrapped source
        return getattr(self.inner, attr)

    def rows(self) -> list[dict]:
        """The noted frames as {"index", "file", "problem"} rows, in frame order."""
        return [{"index": i, "file": self.inner.name(i), "problem": p} for i, p in sorted(self.problems.items())]


def check_mode(skip_bad_frames: bool) -> str:
    """`open_sequence`'s check_images for a command: strict ("exists") unless bad frames are skipped."""
    return "none" if skip_bad_frames else "exists"


def note_bad_frames(seq: Sequence) -> NotedImages:
    """Wrap the sequence's images so that unreadable frames are warned about and listed; returns the wrapper."""
    noted = NotedImages(seq.images)
    seq.images = noted
    return noted
