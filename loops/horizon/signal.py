"""The 1D horizon signal: a vertical band around the horizon, summed, sampled every few columns (paper §3).

The sum (not the mean) is what the paper uses; the detector divides its responses by the band height so the
threshold stays in grey levels whatever the band.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from loops.errors import LoopsError
from loops.horizon.params import HorizonParams, SampleMode


class HorizonError(LoopsError):
    """A horizon that cannot be read from an image (outside it, or too short a signal)."""


@dataclass(frozen=True)
class HorizonLine:
    """Where the horizon crosses the image: its row at the left edge (column 0) and at the right edge (column W-1).

    A level camera has row_left == row_right; a rolled one (the robot's kinematics tell) has them differ.
    """

    row_left: float
    row_right: float

    @classmethod
    def level(cls, row: float) -> "HorizonLine":
        return cls(float(row), float(row))

    def row_at(self, x: np.ndarray, width: int) -> np.ndarray:
        t = np.asarray(x, dtype=np.float64) / max(width - 1, 1)
        return self.row_left + (self.row_right - self.row_left) * t


def as_gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        return cv2.cvtColor(np.ascontiguousarray(image), code)
    raise HorizonError(f"expected a grey (H, W) or colour (H, W, 3) image, got an array of shape {image.shape}")


def _band_start(row: float, band: int) -> int:
    # The band holds rows [r0, r0 + band): centred on the horizon row (row - band/2 .. row + band/2 - 1).
    return int(np.floor(row + 0.5)) - band // 2


def _check_band(r0_min: int, r0_max: int, band: int, height: int, what: str) -> None:
    if r0_min < 0 or r0_max + band > height:
        raise HorizonError(
            f"{what} with a {band}-pixel band needs image rows {r0_min}..{r0_max + band - 1}, but the image has "
            f"rows 0..{height - 1}; give a horizon inside the image or a smaller band_height")


def horizon_signal(image: np.ndarray, horizon: float | HorizonLine, params: HorizonParams = HorizonParams()
                   ) -> np.ndarray:
    """The 1D signal of `image` along `horizon` (a row, or a HorizonLine): float64, one value per sample.

    Sample k holds the sum of params.band_height pixels centred on the horizon: in column k * step
    (SampleMode.COLUMN, the paper) or over columns [k * step, (k + 1) * step) (SampleMode.BOX); see
    `sample_columns`. Raises HorizonError when the band leaves the image.
    """
    image = as_gray(np.asarray(image))
    height, width = image.shape
    band, step = params.band_height, params.step
    box = params.sample_mode is SampleMode.BOX
    if isinstance(horizon, HorizonLine) and horizon.row_left != horizon.row_right:
        cols = np.arange(0, (width // step) * step if box else width, 1 if box else step)
        rows = horizon.row_at(cols, width)
        if not np.all(np.isfinite(rows)):
            raise HorizonError(f"horizon line {horizon} is not finite")
        r0 = np.floor(rows + 0.5).astype(np.intp) - band // 2
        _check_band(int(r0.min()), int(r0.max()), band, height,
                    f"horizon line from row {horizon.row_left:g} (left) to {horizon.row_right:g} (right)")
        idx_r = r0[None, :] + np.arange(band)[:, None]
        sig = image[idx_r, cols[None, :]].sum(axis=0, dtype=np.float64)
        return sig.reshape(-1, step).sum(axis=1) if box else sig
    row = horizon.row_left if isinstance(horizon, HorizonLine) else horizon
    try:
        row = float(row)
    except (TypeError, ValueError):
        raise HorizonError(f"horizon row must be a number, got {row!r}") from None
    if not np.isfinite(row):
        raise HorizonError(f"horizon row must be finite, got {row}")
    r0 = _band_start(row, band)
    _check_band(r0, r0, band, height, f"horizon row {row:g}")
    if box:
        n = width // step
        band_img = image[r0:r0 + band, :n * step]
        if band_img.dtype == np.uint8:
            sums = cv2.reduce(band_img, 0, cv2.REDUCE_SUM, dtype=cv2.CV_32S)  # 3x faster than numpy here
        else:
            sums = band_img.sum(axis=0, dtype=np.float64)
        return sums.reshape(n, step).sum(axis=1, dtype=np.float64)
    return np.add.reduce(image[r0:r0 + band, ::step], axis=0, dtype=np.float64)


def sample_columns(n: int, params: HorizonParams) -> np.ndarray:
    """Image column (pixels) each of the n samples stands for: k * step, or the box centre in SampleMode.BOX."""
    x0 = (params.step - 1) / 2.0 if params.sample_mode is SampleMode.BOX else 0.0
    return x0 + params.step * np.arange(n)
