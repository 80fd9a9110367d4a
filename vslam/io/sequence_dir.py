"""The sequence directory format of DESIGN.md: read with validation, write atomically.

    camera.yaml      width height fx fy cx cy distortion [camera_height] [mount] [tilt]
    frames.csv       timestamp,image
    odometry.csv     optional: timestamp,v,omega
    imu.csv          optional: timestamp,gyro_z
    groundtruth.txt  optional: TUM "timestamp tx ty tz qx qy qz qw"
"""
from __future__ import annotations

import math
import os
import shutil
import tempfile
import warnings
from pathlib import Path

import cv2
import numpy as np
import yaml

from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.camera import CameraModel
from odometry.shared.tum import TumFormatError, format_tum, read_tum
from vslam.errors import (
    CalibrationError,
    EmptySequenceError,
    ImageReadError,
    MissingFileError,
    SequenceError,
    SkippedInputWarning,
    TimestampOrderError,
)
from vslam.image_file import read_image_file
from vslam.io.csvstreams import format_csv, read_csv_columns
from vslam.sequence import FileImages, GyroStream, Sequence, Trajectory, WheelOdometry

CAMERA_FILE = "camera.yaml"
FRAMES_FILE = "frames.csv"
ODOMETRY_FILE = "odometry.csv"
IMU_FILE = "imu.csv"
GROUNDTRUTH_FILE = "groundtruth.txt"

FRAMES_HEADER = ("timestamp", "image")
ODOMETRY_HEADER = ("timestamp", "v", "omega")
IMU_HEADER = ("timestamp", "gyro_z")

CAMERA_REQUIRED = ("width", "height", "fx", "fy", "cx", "cy", "distortion")
CAMERA_OPTIONAL = ("camera_height", "mount", "tilt")
_CAMERA_LISTS = {"distortion": (4, 5), "mount": (3,), "tilt": (2,)}


def is_sequence_dir(path: Path) -> bool:
    return Path(path).is_dir() and (Path(path) / FRAMES_FILE).is_file()


def read_camera_yaml(path: str | os.PathLike) -> CameraModel:
    """Parse and validate camera.yaml; errors name the file, line and field."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "calibration file not found")
    text = path.read_text(encoding="utf-8")
    try:
        node = yaml.compose(text)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise CalibrationError(path, f"not valid YAML ({getattr(exc, 'problem', exc)})",
                               line=None if mark is None else mark.line + 1) from None
    if not isinstance(data, dict):
        raise CalibrationError(path, "expected a mapping of calibration fields")
    lines = {}
    if node is not None and hasattr(node, "value") and isinstance(node.value, list):
        for k, _v in node.value:
            lines[getattr(k, "value", None)] = k.start_mark.line + 1
    for key in data:
        if key not in CAMERA_REQUIRED + CAMERA_OPTIONAL:
            raise CalibrationError(path, "unknown calibration field (expected "
                                   f"{', '.join(CAMERA_REQUIRED + CAMERA_OPTIONAL)})", line=lines.get(key), field=str(key))
    for key in CAMERA_REQUIRED:
        if key not in data:
            raise CalibrationError(path, "missing calibration field", field=key)
    for key, value in data.items():
        if key in _CAMERA_LISTS:
            if not isinstance(value, (list, tuple)) or len(value) not in _CAMERA_LISTS[key]:
                raise CalibrationError(path, f"expected a list of {' or '.join(map(str, _CAMERA_LISTS[key]))} numbers",
                                       line=lines.get(key), field=key)
            items = value
        else:
            items = [value]
        for v in items:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise CalibrationError(path, f"expected a number, got {v!r}", line=lines.get(key), field=key)
            if not math.isfinite(v):
                raise CalibrationError(path, f"{v} is not a finite number", line=lines.get(key), field=key)
    for key in ("width", "height"):
        if data[key] != int(data[key]) or data[key] <= 0:
            raise CalibrationError(path, "expected a positive integer", line=lines.get(key), field=key)
    for key in ("fx", "fy"):
        if data[key] <= 0:
            raise CalibrationError(path, "focal length must be positive", line=lines.get(key), field=key)
    if "camera_height" in data and data["camera_height"] <= 0:
        raise CalibrationError(path, "camera height must be positive (metres)", line=lines.get("camera_height"),
                               field="camera_height")
    try:
        return CameraModel.from_dict(data)
    except (KeyError, ValueError) as exc:
        raise CalibrationError(path, str(exc)) from None


def camera_yaml_text(camera: CameraModel) -> str:
    d = camera.to_dict()
    lines = [f"width: {d['width']}", f"height: {d['height']}"]
    lines += [f"{k}: {float(d[k])!r}" for k in ("fx", "fy", "cx", "cy")]
    lines.append("distortion: [" + ", ".join(repr(float(x)) for x in d["distortion"]) + "]   # k1 k2 p1 p2 k3")
    if "camera_height" in d:
        lines.append(f"camera_height: {float(d['camera_height'])!r}   # metres, optical centre to floor")
    lines.append("mount: [" + ", ".join(repr(float(x)) for x in d["mount"]) + "]   # x, y (m), yaw (rad) in base frame")
    if "tilt" in d:
        lines.append("tilt: [" + ", ".join(repr(float(x)) for x in d["tilt"]) + "]   # roll, pitch (rad)")
    return "\n".join(lines) + "\n"


def write_camera_yaml(path: str | os.PathLike, camera: CameraModel) -> None:
    atomic_write_text(path, camera_yaml_text(camera))


def read_sequence_dir(root: str | os.PathLike, check_images: str = "exists", require_camera: bool = True) -> Sequence:
    """Read and validate a sequence directory.

    check_images: "none" (trust frames.csv), "exists" (every image file exists; default) or "decode"
    (decode every image: slow, finds corrupt files up front).
    require_camera: False for uses that need no calibration (place recognition): a missing camera.yaml then gives
    camera None; a present one is still validated.
    """
    root = Path(root)
    if not root.is_dir():
        raise MissingFileError(root, "sequence directory not found")
    camera = None if not require_camera and not (root / CAMERA_FILE).exists() else read_camera_yaml(root / CAMERA_FILE)
    frames = read_csv_columns(root / FRAMES_FILE, FRAMES_HEADER, text_columns=("image",))
    if len(frames["timestamp"]) == 0:
        raise EmptySequenceError(root / FRAMES_FILE, "no frames listed")
    images = FileImages(root, frames["image"])
    _check_images(root / FRAMES_FILE, images, check_images)
    odo = imu = gt = None
    if (root / ODOMETRY_FILE).exists():
        c = read_csv_columns(root / ODOMETRY_FILE, ODOMETRY_HEADER)
        odo = WheelOdometry(c["timestamp"], c["v"], c["omega"]) if _has_rows(root / ODOMETRY_FILE, c) else None
    if (root / IMU_FILE).exists():
        c = read_csv_columns(root / IMU_FILE, IMU_HEADER)
        imu = GyroStream(c["timestamp"], c["gyro_z"]) if _has_rows(root / IMU_FILE, c) else None
    if (root / GROUNDTRUTH_FILE).exists():
        gt = read_groundtruth(root / GROUNDTRUTH_FILE)
    return Sequence(timestamps=frames["timestamp"], images=images, camera=camera, odometry=odo, imu=imu,
                    groundtruth=gt, root=root, name=root.name, format="sequence")


def _has_rows(path: Path, columns: dict) -> bool:
    """A stream file with a header and no samples is read as absent, with a warning naming it."""
    if len(columns["timestamp"]):
        return True
    warnings.warn(SkippedInputWarning(f"{path}: no samples (header only): the stream is ignored"), stacklevel=3)
    return False


def read_groundtruth(path: Path) -> Trajectory:
    try:
        t, p = read_tum(path)
    except TumFormatError as exc:
        raise SequenceError(path, str(exc).split(": ", 1)[-1]) from None
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        raise TimestampOrderError(path, f"timestamp {float(t[bad[0] + 1])!r} does not increase "
                                        f"(previous {float(t[bad[0]])!r})",
                                  field="timestamp")
    return Trajectory(t, p)


def _check_images(listing: Path, images: FileImages, mode: str) -> None:
    if mode == "none":
        return
    if mode not in ("exists", "decode"):
        raise ValueError(f"check_images must be none, exists or decode, got {mode!r}")
    for i in range(len(images)):
        p = images.path(i)
        if not p.is_file():
            raise ImageReadError(listing, f"image file {p} is missing", line=i + 2, field="image")
        if mode == "decode":
            try:
                read_image_file(p, cv2.IMREAD_UNCHANGED)
            except ImageReadError as exc:
                raise ImageReadError(listing, f"image file {p}: {exc.problem}", line=i + 2, field="image") from None


# ---------------------------------------------------------------------------------------------------- writing

class SequenceWriter:
    """Write a sequence directory frame by frame; nothing appears at `root` until `close()` succeeds.

    Frames go to a hidden temporary directory beside `root`, which is renamed into place at the end,
    so an interrupted run never leaves a half-written sequence that looks complete.
    """

    def __init__(self, root: str | os.PathLike, camera: CameraModel, image_ext: str = ".png",
                 overwrite: bool = False, jpeg_quality: int = 95):
        self.root = Path(root)
        if self.root.exists() and not overwrite:
            raise FileExistsError(f"{self.root} already exists (use overwrite to replace it)")
        self.root.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.root.name}.", dir=self.root.parent))
        (self.tmp / "images").mkdir()
        self.camera = camera
        self.image_ext = image_ext if image_ext.startswith(".") else "." + image_ext
        self.overwrite = overwrite
        self._params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if self.image_ext in (".jpg", ".jpeg") else \
            [cv2.IMWRITE_PNG_COMPRESSION, 1] if self.image_ext == ".png" else []
        self.timestamps: list[float] = []
        self.names: list[str] = []
        self._closed = False

    def add_frame(self, timestamp: float, image: np.ndarray | None = None, raw_bytes: bytes | None = None,
                  name: str | None = None) -> str:
        """Add one frame. Give either a decoded image or raw file bytes (written as is, e.g. a corrupt frame)."""
        if self.timestamps and timestamp <= self.timestamps[-1]:
            raise ValueError(f"frame timestamps must increase: {timestamp} after {self.timestamps[-1]}")
        rel = f"images/{name or f'{len(self.names):06d}{self.image_ext}'}"
        path = self.tmp / rel
        if raw_bytes is not None:
            path.write_bytes(raw_bytes)
        elif not cv2.imwrite(str(path), image, self._params):
            raise OSError(f"could not write image {path}")
        self.timestamps.append(float(timestamp))
        self.names.append(rel)
        return rel

    def close(self, odometry: WheelOdometry | None = None, imu: GyroStream | None = None,
              groundtruth: Trajectory | None = None, extra_files: dict[str, str] | None = None) -> Path:
        write_camera_yaml(self.tmp / CAMERA_FILE, self.camera)
        atomic_write_text(self.tmp / FRAMES_FILE,
                          format_csv(FRAMES_HEADER, [np.asarray(self.timestamps), self.names]))
        if odometry is not None:
            atomic_write_text(self.tmp / ODOMETRY_FILE, format_csv(ODOMETRY_HEADER,
                                                                   [odometry.timestamps, odometry.v, odometry.omega]))
        if imu is not None:
            atomic_write_text(self.tmp / IMU_FILE, format_csv(IMU_HEADER, [imu.timestamps, imu.gyro_z]))
        if groundtruth is not None:
            atomic_write_text(self.tmp / GROUNDTRUTH_FILE, format_tum(groundtruth.timestamps, groundtruth.poses))
        for name, text in (extra_files or {}).items():
            atomic_write_text(self.tmp / name, text)
        if self.root.exists():
            old = self.root.with_name(f".{self.root.name}.old")
            shutil.rmtree(old, ignore_errors=True)
            os.replace(self.root, old)
            os.replace(self.tmp, self.root)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(self.tmp, self.root)
        self._closed = True
        return self.root

    def abort(self) -> None:
        if not self._closed:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def __enter__(self) -> "SequenceWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()


def write_sequence(seq: Sequence, root: str | os.PathLike, image_ext: str = ".png", overwrite: bool = False) -> Path:
    """Write any `Sequence` (e.g. converted from KITTI or a video) in the sequence directory format."""
    camera = seq.require_camera()
    with SequenceWriter(root, camera, image_ext=image_ext, overwrite=overwrite) as w:
        if isinstance(seq.images, FileImages):
            # copy the files byte for byte: re-encoding would lose information
            for i, t in enumerate(seq.timestamps):
                src = seq.images.path(i)
                if not src.is_file():
                    raise ImageReadError(src, "image file is missing")
                w.add_frame(float(t), raw_bytes=src.read_bytes(), name=f"{i:06d}{src.suffix.lower()}")
        else:
            for fr in seq.frames():
                w.add_frame(fr.timestamp, fr.image)
        return w.close(odometry=seq.odometry, imu=seq.imu, groundtruth=seq.groundtruth)
