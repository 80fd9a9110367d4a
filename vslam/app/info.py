"""A sequence's summary and validation (`vslam info`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vslam.io import open_sequence
from vslam.sequence import Sequence


def sequence_summary(seq: Sequence) -> str:
    """Frames, rate, camera (and its floor footprint when downward), streams and ground truth, one per line."""
    lines = [f"sequence   {seq.root or seq.name}  ({seq.format})",
             f"frames     {len(seq)}", f"duration   {seq.duration:.2f} s"]
    if len(seq) > 1:
        dt = np.diff(seq.timestamps)
        lines.append(f"rate       {1 / np.median(dt):.2f} Hz (median), largest gap {dt.max():.3f} s")
    cam = seq.camera
    if cam is None:
        lines.append("camera     none (no calibration)")
    else:
        lines.append(f"camera     {cam.width}x{cam.height}  fx {cam.fx:g} fy {cam.fy:g}  cx {cam.cx:g} cy {cam.cy:g}  "
                     f"distortion [{', '.join(f'{d:g}' for d in cam.distortion)}]")
        if cam.camera_height is not None:
            fp = cam.footprint()
            span = fp.max(axis=0) - fp.min(axis=0)
            lines.append(f"downward   height {cam.camera_height:g} m, footprint {span[0]:.3f} x {span[1]:.3f} m, "
                         f"{cam.ground_resolution() * 1000:.2f} mm/px, mount [{', '.join(f'{m:g}' for m in cam.mount)}]")
    lines.append(f"odometry   {len(seq.odometry)} samples" if seq.odometry is not None else "odometry   absent")
    lines.append(f"imu        {len(seq.imu)} samples" if seq.imu is not None else "imu        absent")
    if seq.groundtruth is not None:
        length = seq.path_length()   # None for a single pose
        lines.append(f"groundtruth {len(seq.groundtruth)} poses, path length "
                     + (f"{length:.2f} m" if length is not None else "n/a"))
    else:
        lines.append("groundtruth absent")
    return "\n".join(lines)


def describe_sequence(path: str | Path, camera: str | None = None, fps: float = 10.0, decode: bool = False) -> str:
    """Open (and so validate) a sequence and summarise it; `decode` reads every image (finds corrupt files).
    Invalid input raises a SequenceError naming the file, line and field."""
    seq = open_sequence(path, camera=camera, fps=fps, check_images="decode" if decode else "exists")
    if decode and seq.format != "sequence":   # sequence directories were decoded while opening
        for i in range(len(seq)):
            seq.image(i)                     # ImageReadError names the file (truncated, corrupt, missing)
    return sequence_summary(seq)
