"""The in-memory sequence: calibration, frame timestamps, lazily loaded images and optional sensor streams.

Images are decoded only when asked for, so a 100k-frame sequence costs a few arrays of timestamps and
file names. Readers for every supported on-disk format live in `vslam.io` and all return a `Sequence`;
`vslam.io.open_sequence(path)` picks the reader.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Protocol

import cv2
import numpy as np

from odometry.shared.camera import CameraModel
from odometry.shared.poses import wrap_angle
from odometry.shared.tum import tum_to_se2
from vslam.errors import ImageReadError, VslamError
from vslam.image_file import read_image_file

EXACT_STAMP_S = 1e-6    # s: stamps this close name the same instant (TUM text keeps 6 decimals)
# s: where no interpolation is allowed (a gap wider than max_gap, e.g. one GNSS fix per photograph at 0.14 Hz), a pose
# this close to the frame still stands for it; evo's and our ATE association tolerance, so both evaluations agree
NEAREST_STAMP_S = 0.01


@dataclass(frozen=True)
class WheelOdometry:
    """Wheel odometry stream: forward speed v (m/s) and yaw rate omega (rad/s)."""

    timestamps: np.ndarray
    v: np.ndarray
    omega: np.ndarray

    def __len__(self) -> int:
        return len(self.timestamps)


@dataclass(frozen=True)
class GyroStream:
    """Gyro yaw rate gyro_z (rad/s)."""

    timestamps: np.ndarray
    gyro_z: np.ndarray

    def __len__(self) -> int:
        return len(self.timestamps)


@dataclass(frozen=True)
class Trajectory:
    """Timestamped 3D poses, TUM columns tx ty tz qx qy qz qw."""

    timestamps: np.ndarray
    poses: np.ndarray

    def __len__(self) -> int:
        return len(self.timestamps)

    def planar(self) -> np.ndarray:
        """(N, 3) planar poses x, y, heading."""
        return tum_to_se2(self.poses)

    def planar_at(self, t: np.ndarray, max_gap: float | None = None) -> np.ndarray:
        """Planar poses linearly interpolated at times `t` (heading interpolated on the circle).
        Times outside the trajectory, or in a gap wider than `max_gap` seconds, give NaN rows."""
        t = np.asarray(t, dtype=float)
        p = self.planar()
        ts = self.timestamps
        out = np.full((len(t), 3), np.nan)
        if len(ts) == 0:
            return out
        # a stamp within 1 us of a pose is that pose: TUM files carry 6 decimals, frames.csv may carry more (a
        # 0.14 Hz frame at 7.142857142857 s against ground truth at 7.142857 s), and at a low rate the gap to the
        # next pose is wider than max_gap
        j = np.clip(np.searchsorted(ts, t - EXACT_STAMP_S, side="left"), 0, len(ts) - 1)
        near = np.abs(ts[j] - t) <= EXACT_STAMP_S
        i = np.where(near, j, np.searchsorted(ts, t, side="right") - 1)
        exact = near
        out[exact] = p[i[exact]]
        inside = (i >= 0) & (i < len(ts) - 1) & ~exact
        if np.any(inside):
            i0 = i[inside]
            t0, t1 = ts[i0], ts[i0 + 1]
            a = (t[inside] - t0) / (t1 - t0)
            d = p[i0 + 1] - p[i0]
            d[:, 2] = wrap_angle(d[:, 2])
            val = p[i0] + a[:, None] * d
            val[:, 2] = wrap_angle(val[:, 2])
            if max_gap is not None:
                val[(t1 - t0) > max_gap] = np.nan
            out[inside] = val
        # still empty (a gap, or just outside the ends): the nearest pose within NEAREST_STAMP_S, if any
        empty = np.isnan(out[:, 0])
        if np.any(empty):
            k = np.clip(np.searchsorted(ts, t[empty]), 1, max(len(ts) - 1, 1))
            k = np.where(np.abs(ts[k - 1] - t[empty]) <= np.abs(ts[np.minimum(k, len(ts) - 1)] - t[empty]),
                         k - 1, np.minimum(k, len(ts) - 1))
            ok = np.abs(ts[k] - t[empty]) <= NEAREST_STAMP_S
            rows = np.nonzero(empty)[0][ok]
            out[rows] = p[k[ok]]
        return out


@dataclass(frozen=True)
class Frame:
    index: int
    timestamp: float
    image: np.ndarray
    source: str  # file name (or "video.mp4#123") for error messages and logs


class ImageSource(Protocol):
    """Where frame images come from; `read` raises ImageReadError naming the file."""

    def __len__(self) -> int: ...

    def read(self, index: int, gray: bool = False) -> np.ndarray: ...

    def name(self, index: int) -> str: ...


class FileImages:
    """Images stored as one file per frame, paths relative to `root`."""

    def __init__(self, root: Path, relpaths: list[str]):
        self.root = Path(root)
        self.relpaths = relpaths

    def __len__(self) -> int:
        return len(self.relpaths)

    def path(self, index: int) -> Path:
        return self.root / self.relpaths[index]

    def name(self, index: int) -> str:
        return str(self.path(index))

    def read(self, index: int, gray: bool = False) -> np.ndarray:
        # truncated files are refused, decoder warnings name the file (vslam.image_file)
        return read_image_file(self.path(index), cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR)


class VideoImages:
    """Frames of a video file; sequential reads are cheap, random access seeks."""

    def __init__(self, path: Path, count: int):
        self.path = Path(path)
        self.count = count
        self._cap: cv2.VideoCapture | None = None
        self._next = 0

    def __len__(self) -> int:
        return self.count

    def name(self, index: int) -> str:
        return f"{self.path}#{index}"

    def read(self, index: int, gray: bool = False) -> np.ndarray:
        if not 0 <= index < self.count:
            raise IndexError(index)
        if self._cap is None:
            self._cap = cv2.VideoCapture(str(self.path))
            self._next = 0
        if index != self._next:
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, index)
        ok, img = self._cap.read()
        self._next = index + 1
        if not ok or img is None:
            raise ImageReadError(self.path, f"frame {index} cannot be decoded")
        return cv2.cvtColor(img, cv2.COLOR_BGR2GRAY) if gray else img

    def __getstate__(self):  # VideoCapture cannot be pickled; reopen lazily
        return {**self.__dict__, "_cap": None, "_next": 0}


@dataclass
class Sequence:
    """A recorded (or simulated) sequence. `camera` is None when no calibration is known."""

    timestamps: np.ndarray
    images: ImageSource
    camera: CameraModel | None = None
    odometry: WheelOdometry | None = None
    imu: GyroStream | None = None
    groundtruth: Trajectory | None = None
    root: Path | None = None
    name: str = ""
    format: str = "sequence"
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.timestamps)

    def image(self, index: int, gray: bool = False) -> np.ndarray:
        return self.images.read(index, gray=gray)

    def frames(self, gray: bool = False, start: int = 0, stop: int | None = None, step: int = 1) -> Iterator[Frame]:
        """Frames decoded one at a time (memory stays bounded whatever the length)."""
        stop = len(self) if stop is None else min(stop, len(self))
        for i in range(start, stop, step):
            yield Frame(i, float(self.timestamps[i]), self.images.read(i, gray=gray), self.images.name(i))

    @property
    def duration(self) -> float:
        return float(self.timestamps[-1] - self.timestamps[0]) if len(self) > 1 else 0.0

    def groundtruth_planar(self, max_gap: float | None = 0.5) -> np.ndarray | None:
        """Ground-truth planar poses at the frame timestamps (NaN where not covered), or None."""
        if self.groundtruth is None:
            return None
        return self.groundtruth.planar_at(self.timestamps, max_gap=max_gap)

    def path_length(self) -> float | None:
        """Length of the ground-truth path in metres (3D), or None without ground truth."""
        if self.groundtruth is None or len(self.groundtruth) < 2:
            return None
        return float(np.sum(np.linalg.norm(np.diff(self.groundtruth.poses[:, :3], axis=0), axis=1)))

    def require_camera(self) -> CameraModel:
        if self.camera is None:
            raise VslamError(f"sequence {self.root or self.name} has no calibration: give one with --camera camera.yaml")
        return self.camera
