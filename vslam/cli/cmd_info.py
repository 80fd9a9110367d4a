"""`vslam info SEQ`: summarise and validate a sequence."""
from __future__ import annotations

import argparse

NAME = "info"
HELP = "summarise and validate a sequence (exit code 2 and the file/field on invalid input)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", help="sequence directory, TUM RGB-D / KITTI folder, image folder or video")
    p.add_argument("--camera", help="camera.yaml to use (image folders and videos)")
    p.add_argument("--fps", type=float, default=10.0, help="frame rate for image folders without timestamps")
    p.add_argument("--decode", action="store_true", help="decode every image (finds corrupt files; slower)")


def summary(seq) -> str:
    import numpy as np

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
        lines.append(f"groundtruth {len(seq.groundtruth)} poses, path length {seq.path_length():.2f} m")
    else:
        lines.append("groundtruth absent")
    return "\n".join(lines)


def run(a: argparse.Namespace) -> int:
    from vslam.io import open_sequence

    seq = open_sequence(a.sequence, camera=a.camera, fps=a.fps, check_images="decode" if a.decode else "exists")
    print(summary(seq))
    print("valid      yes")
    return 0
