"""Reading one image file with its problems named: missing, empty, truncated, undecodable.

OpenCV decodes a JPEG cut short as a complete image (the missing part grey) and only libjpeg prints a warning on
the process's stderr, without the file's name; libpng does the same for PNG. So the file's end is checked before
decoding (a JPEG must hold an end-of-image marker after its last scan, a PNG its IEND chunk after its last IDAT),
and whatever the decoders print while decoding is captured and re-issued as an `ImageDecodeWarning` naming the
file.
"""
from __future__ import annotations

import os
import tempfile
import threading
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from vslam.errors import ImageReadError

JPEG_SOI, JPEG_SOS, JPEG_EOI = b"\xff\xd8", b"\xff\xda", b"\xff\xd9"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

_STDERR_LOCK = threading.Lock()   # one capture at a time: fd 2 is process-wide


class ImageDecodeWarning(UserWarning):
    """A decoder complained about an image it could still decode (the message names the file)."""


def truncation_problem(data: bytes) -> str | None:
    """Why the bytes of a JPEG or PNG file are incomplete, or None (other formats: None)."""
    if data.startswith(JPEG_SOI):
        sos = data.rfind(JPEG_SOS)
        # inside entropy-coded data 0xFF is stuffed (FF 00), so an EOI after the last scan header is the real end
        if sos < 0 or data.find(JPEG_EOI, sos + 2) < 0:
            return "truncated JPEG (no end-of-image marker after the last scan)"
    elif data.startswith(PNG_SIGNATURE):
        if data.rfind(b"IEND") < max(data.rfind(b"IDAT"), len(PNG_SIGNATURE)):
            return "truncated PNG (no IEND chunk after the image data)"
    return None


@contextmanager
def captured_stderr() -> Iterator[list[str]]:
    """Collect what C libraries write to file descriptor 2 inside the block (the list is filled on exit)."""
    lines: list[str] = []
    with _STDERR_LOCK:
        try:
            saved = os.dup(2)
        except OSError:      # no stderr at all: nothing to capture
            yield lines
            return
        with tempfile.TemporaryFile() as tmp:
            os.dup2(tmp.fileno(), 2)
            try:
                yield lines
            finally:
                os.dup2(saved, 2)
                os.close(saved)
                tmp.seek(0)
                lines += [ln for ln in tmp.read().decode("utf-8", "replace").splitlines() if ln.strip()]


def read_image_file(path: str | os.PathLike, flag: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """Decode an image file with `cv2.imread` flags; ImageReadError names the file and the problem (missing,
    empty, truncated, not decodable). Decoder warnings become ImageDecodeWarning naming the file."""
    p = Path(path)
    if not p.is_file():
        raise ImageReadError(p, "image file is missing")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ImageReadError(p, f"cannot read the file ({exc.strerror or exc})") from None
    if not data:
        raise ImageReadError(p, "image file is empty")
    problem = truncation_problem(data)
    if problem:
        raise ImageReadError(p, problem)
    with captured_stderr() as messages:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), flag)
    for m in messages:
        warnings.warn(ImageDecodeWarning(f"{p}: {m}"), stacklevel=2)
    if img is None:
        raise ImageReadError(p, "image cannot be decoded (corrupt or not an image)")
    return img
