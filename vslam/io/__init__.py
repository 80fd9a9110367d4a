"""Reading and writing sequences. `open_sequence(path)` accepts any supported layout:

- a sequence directory (camera.yaml + frames.csv + optional streams; DESIGN.md),
- a TUM RGB-D folder (rgb.txt), a KITTI odometry folder (image_0/ + calib.txt [+ times.txt, poses]),
- a plain image folder, or a video file (with camera.yaml beside it or `camera=`).
"""
from __future__ import annotations

import os
from pathlib import Path

from odometry.shared.camera import CameraModel
from vslam.errors import MissingFileError, SequenceError
from vslam.io.public_formats import (
    VIDEO_EXTENSIONS,
    is_kitti,
    is_tum_rgbd,
    read_image_folder,
    read_kitti,
    read_tum_rgbd,
    read_video,
)
from vslam.io.sequence_dir import (
    SequenceWriter,
    is_sequence_dir,
    read_camera_yaml,
    read_sequence_dir,
    write_camera_yaml,
    write_sequence,
)
from vslam.sequence import Sequence

__all__ = ["SequenceWriter", "open_sequence", "read_camera_yaml", "read_image_folder", "read_kitti",
           "read_sequence_dir", "read_tum_rgbd", "read_video", "write_camera_yaml", "write_sequence"]


def open_sequence(path: str | os.PathLike, camera: CameraModel | str | None = None, fps: float = 10.0,
                  check_images: str = "exists") -> Sequence:
    """Open any supported sequence layout (see module docstring). `camera` overrides the calibration."""
    p = Path(path)
    if not p.exists():
        raise MissingFileError(p, "no such file or directory")
    if p.is_file():
        if p.suffix.lower() in VIDEO_EXTENSIONS:
            return read_video(p, camera)
        raise SequenceError(p, f"not a sequence: expected a directory or a video ({', '.join(VIDEO_EXTENSIONS)})")
    if is_sequence_dir(p):
        seq = read_sequence_dir(p, check_images=check_images)
        if camera is not None:
            seq.camera = camera if isinstance(camera, CameraModel) else read_camera_yaml(camera)
        return seq
    if is_tum_rgbd(p):
        return read_tum_rgbd(p, camera)
    if is_kitti(p):
        return read_kitti(p, camera, fps=fps)
    return read_image_folder(p, camera, fps=fps)
