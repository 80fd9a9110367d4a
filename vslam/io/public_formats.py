"""Readers that turn public dataset layouts into a `Sequence`: TUM RGB-D, KITTI odometry, an image folder,
a video file. Fields a format lacks stay None; a calibration can always be supplied explicitly.
"""
from __future__ import annotations

import math
import os
import re
from pathlib import Path

import cv2
import numpy as np

from odometry.shared.camera import CameraModel
from odometry.shared.tum import se3_matrices_to_tum
from vslam.errors import (
    CsvFormatError,
    EmptySequenceError,
    ImageReadError,
    MissingFileError,
    SequenceError,
    TimestampOrderError,
    VslamError,
)
from vslam.image_file import read_image_file
from vslam.io.sequence_dir import CAMERA_FILE, read_camera_yaml, read_groundtruth
from vslam.sequence import FileImages, Sequence, Trajectory, VideoImages

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
VIDEO_EXTENSIONS = (".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v")

# Published TUM RGB-D colour camera calibrations (ROS default, "fr1/fr2/fr3" in the benchmark's docs).
TUM_RGBD_CAMERAS = {
    "freiburg1": dict(fx=517.3, fy=516.5, cx=318.6, cy=255.3, distortion=(0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    "freiburg2": dict(fx=520.9, fy=521.0, cx=325.1, cy=249.7, distortion=(0.2312, -0.7849, -0.0033, -0.0001, 0.9172)),
    "freiburg3": dict(fx=535.4, fy=539.2, cx=320.1, cy=247.6, distortion=(0.0, 0.0, 0.0, 0.0, 0.0)),
}


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _listed_images(folder: Path) -> list[str]:
    return sorted((p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS and p.is_file()),
                  key=_natural_key)


def _camera_for(root: Path, camera: CameraModel | str | os.PathLike | None, size: tuple[int, int] | None
                ) -> CameraModel | None:
    """An explicit camera (model or camera.yaml path) wins; else camera.yaml beside the data; else None."""
    if isinstance(camera, CameraModel):
        return camera
    if camera is not None:
        return read_camera_yaml(camera)
    if (root / CAMERA_FILE).is_file():
        return read_camera_yaml(root / CAMERA_FILE)
    return None


def _check_increasing(path: Path, t: np.ndarray) -> None:
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if len(bad):
        raise TimestampOrderError(path, f"timestamp {t[bad[0] + 1]!r} does not increase", line=int(bad[0]) + 2)


# ---------------------------------------------------------------------------------------------------- TUM RGB-D

def is_tum_rgbd(path: Path) -> bool:
    return Path(path).is_dir() and (Path(path) / "rgb.txt").is_file()


def read_tum_rgbd(root: str | os.PathLike, camera: CameraModel | str | None = None) -> Sequence:
    """A TUM RGB-D dataset folder (rgb.txt, rgb/*.png, optional groundtruth.txt). The colour camera's published
    calibration is used when the folder name says freiburg1/2/3 and no camera is given."""
    root = Path(root)
    listing = root / "rgb.txt"
    ts, names = [], []
    with open(listing, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            s = line.split("#", 1)[0].strip()
            if not s:
                continue
            parts = s.split()
            if len(parts) != 2:
                raise CsvFormatError(listing, "expected 'timestamp filename'", line=lineno)
            try:
                t = float(parts[0])
            except ValueError:
                raise CsvFormatError(listing, f"not a number: {parts[0]!r}", line=lineno, field="timestamp") from None
            if not math.isfinite(t):
                raise CsvFormatError(listing, "timestamp is not finite", line=lineno, field="timestamp")
            ts.append(t)
            names.append(parts[1])
    if not ts:
        raise EmptySequenceError(listing, "no frames listed")
    t = np.asarray(ts)
    _check_increasing(listing, t)
    cam = _camera_for(root, camera, None)
    if cam is None:
        m = re.search(r"freiburg([123])", root.name)
        if m:
            try:   # the image size of the camera; a bad first frame leaves the published 640 x 480
                h, w = read_image_file(root / names[0], cv2.IMREAD_UNCHANGED).shape[:2]
            except ImageReadError:
                h, w = 480, 640
            cam = CameraModel(width=w, height=h, **TUM_RGBD_CAMERAS[f"freiburg{m.group(1)}"])
    gt = read_groundtruth(root / "groundtruth.txt") if (root / "groundtruth.txt").is_file() else None
    return Sequence(timestamps=t, images=FileImages(root, names), camera=cam, groundtruth=gt, root=root,
                    name=root.name, format="tum-rgbd")


# ---------------------------------------------------------------------------------------------------- KITTI

def _kitti_image_dir(root: Path) -> Path | None:
    for name in ("image_0", "image_l", "image_2"):
        if (root / name).is_dir():
            return root / name
    return None


def is_kitti(path: Path) -> bool:
    path = Path(path)
    return path.is_dir() and _kitti_image_dir(path) is not None and (path / "calib.txt").is_file()


def _read_kitti_calib(path: Path) -> np.ndarray:
    """The first projection matrix P0 (3x4) of a KITTI calib.txt ("P0: ..." or a bare first line)."""
    with open(path, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s:
                continue
            label, _, rest = s.partition(":") if ":" in s else ("P0", "", s)
            vals = rest.split()
            if len(vals) != 12:
                raise SequenceError(path, f"expected 12 numbers for {label.strip()}", line=lineno)
            try:
                return np.array([float(v) for v in vals]).reshape(3, 4)
            except ValueError:
                raise SequenceError(path, "non-numeric value", line=lineno) from None
    raise SequenceError(path, "no projection matrix found")


def read_kitti_poses(path: Path) -> np.ndarray:
    """KITTI poses file: 12 numbers per line (3x4 row-major [R|t]) -> (N, 4, 4)."""
    rows = []
    with open(path, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s:
                continue
            vals = s.split()
            if len(vals) != 12:
                raise SequenceError(path, f"expected 12 numbers, got {len(vals)}", line=lineno)
            try:
                rows.append([float(v) for v in vals])
            except ValueError:
                raise SequenceError(path, "non-numeric value", line=lineno) from None
    m = np.tile(np.eye(4), (len(rows), 1, 1))
    if rows:
        m[:, :3, :] = np.asarray(rows).reshape(-1, 3, 4)
    return m


def read_kitti(root: str | os.PathLike, camera: CameraModel | str | None = None, fps: float = 10.0) -> Sequence:
    """A KITTI odometry sequence folder: image_0/ (or image_l/), calib.txt, optional times.txt and poses
    (poses.txt inside, or ../../poses/NN.txt of the official layout). Ground truth is the left camera's pose
    (z forward) as 3D TUM rows."""
    root = Path(root)
    img_dir = _kitti_image_dir(root)
    if img_dir is None:
        raise MissingFileError(root / "image_0", "KITTI image folder not found")
    names = [f"{img_dir.name}/{n}" for n in _listed_images(img_dir)]
    if not names:
        raise EmptySequenceError(img_dir, "no images")
    if (root / "times.txt").is_file():
        t = np.loadtxt(root / "times.txt", ndmin=1)
        if len(t) != len(names):
            raise SequenceError(root / "times.txt", f"{len(t)} timestamps for {len(names)} images")
        _check_increasing(root / "times.txt", t)
    else:
        t = np.arange(len(names)) / fps
    cam = _camera_for(root, camera, None)
    if cam is None:
        P = _read_kitti_calib(root / "calib.txt")
        img = read_image_file(root / names[0], cv2.IMREAD_UNCHANGED)   # ImageReadError names the file
        cam = CameraModel(width=img.shape[1], height=img.shape[0], fx=P[0, 0], fy=P[1, 1], cx=P[0, 2], cy=P[1, 2])
    gt = None
    pose_file = root / "poses.txt"
    if not pose_file.is_file():
        pose_file = root.parent.parent / "poses" / f"{root.name}.txt"
    if pose_file.is_file():
        m = read_kitti_poses(pose_file)
        if len(m) != len(names):
            raise SequenceError(pose_file, f"{len(m)} poses for {len(names)} images")
        gt = Trajectory(t.copy(), se3_matrices_to_tum(m))
    return Sequence(timestamps=t, images=FileImages(root, names), camera=cam, groundtruth=gt, root=root,
                    name=root.name, format="kitti")


# ---------------------------------------------------------------------------------------------------- folder / video

def read_image_folder(root: str | os.PathLike, camera: CameraModel | str | None = None, fps: float = 10.0) -> Sequence:
    """Images of a folder in natural sort order, at `fps` frames per second; camera.yaml in the folder is used
    when no camera is given."""
    root = Path(root)
    if not root.is_dir():
        raise MissingFileError(root, "image folder not found")
    names = _listed_images(root)
    if not names:
        raise EmptySequenceError(root, f"no images ({', '.join(IMAGE_EXTENSIONS)}) in the folder")
    if not fps > 0:
        raise VslamError(f"fps must be positive, got {fps}")
    return Sequence(timestamps=np.arange(len(names)) / fps, images=FileImages(root, names),
                    camera=_camera_for(root, camera, None), root=root, name=root.name, format="folder")


def read_video(path: str | os.PathLike, camera: CameraModel | str | None = None) -> Sequence:
    """A video file; frame timestamps from its frame rate. The calibration comes from `camera` or a camera.yaml
    beside the video."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "video file not found")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise SequenceError(path, "cannot open video (unsupported codec or not a video)")
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    fps = cap.get(cv2.CAP_PROP_FPS) or 0.0
    cap.release()
    if n <= 0:
        raise EmptySequenceError(path, "video has no frames")
    fps = fps if fps > 0 else 30.0
    cam = camera if isinstance(camera, CameraModel) else (read_camera_yaml(camera) if camera is not None else
                                                          _camera_for(path.parent, None, None))
    return Sequence(timestamps=np.arange(n) / fps, images=VideoImages(path, n), camera=cam, root=path.parent,
                    name=path.stem, format="video")
