"""Named images of a folder: an image folder (searched recursively) or a sequence directory's frames.csv. A name is
the image's path relative to the folder (the file name for a flat folder)."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from vslam.errors import VslamError
from vslam.image_file import read_image_file
from vslam.io.sequence_dir import read_sequence_dir

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")


def list_images(folder: str | Path, check_images: str = "exists") -> list[tuple[str, Path]]:
    """(name, path) of the images of an image folder, or of a sequence directory's frames.csv, in order;
    `check_images` as `read_sequence_dir` ("none": listed files may be missing)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: not a directory")
    if (folder / "frames.csv").is_file():
        seq = read_sequence_dir(folder, check_images=check_images, require_camera=False)   # validated: header, timestamps, images exist
        out = [(rel, folder / rel) for rel in seq.images.relpaths]
    else:
        out = [(str(p.relative_to(folder)), p) for p in sorted(folder.rglob("*"))
               if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()]
    if not out:
        raise VslamError(f"{folder}: no images found (expected image files or a frames.csv)")
    return out


def read_image(path: Path) -> np.ndarray:
    """An image file as 8-bit grey or BGR (deeper images scaled to 0-255, alpha dropped); ImageReadError names the
    file (missing, truncated, corrupt)."""
    img = read_image_file(path, cv2.IMREAD_UNCHANGED)
    if img.dtype != "uint8":
        img = cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    if img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img
