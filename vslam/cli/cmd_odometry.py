"""`vslam odometry SEQ --out DIR`: downward visual odometry over a sequence.

Writes DIR/trajectory_vo.txt (TUM, one pose per input frame at the same timestamps, the first at the origin),
DIR/odometry.csv (per-frame motion, covariance, inliers, status) and, when the sequence has wheel odometry,
DIR/trajectory_fused.txt (the wheel/gyro EKF used as the VO's prediction and fallback).
"""
from __future__ import annotations

import argparse

from vslam.errors import VslamError

NAME = "odometry"
HELP = "downward-camera visual odometry: writes trajectory_vo.txt (TUM) and odometry.csv"
DESCRIPTION = (
    "Run the downward-camera visual odometry (LK-tracked keyframe corners, floor back-projection, SVD/Kabsch in "
    "RANSAC, tilt-aware refinement) over a sequence. Wheel odometry and gyro, when present, are fused (EKF) and "
    "used as motion prediction and as the fallback for frames vision cannot measure (flagged in odometry.csv).")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", help="sequence directory (or any format vslam.io.open_sequence reads)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--camera", default=None, help="camera.yaml for formats without one")
    p.add_argument("--preset", default="default", help="VO preset: default, fast")
    p.add_argument("--fusion-preset", default="default", help="wheel/gyro noise preset: default, precise, slippery")
    p.add_argument("--no-fallback", action="store_true",
                   help="ignore wheel odometry and gyro (pure vision; failed frames get a constant-velocity guess)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a VOConfig field, e.g. --set max_features=300 (repeatable)")
    p.add_argument("--quiet", action="store_true")


def _overrides(items: list[str]) -> dict:
    import yaml

    out = {}
    for item in items:
        if "=" not in item:
            raise VslamError(f"--set {item!r}: expected KEY=VALUE")
        k, v = item.split("=", 1)
        out[k.strip()] = yaml.safe_load(v)
    return out


def run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    import numpy as np

    from odometry.fusion import FusionConfig, fuse_wheel_gyro
    from odometry.shared.atomic_io import atomic_write_text
    from odometry.shared.tum import write_tum
    from odometry.vo import VOConfig, VOStatus, run_visual_odometry
    from vslam.io import open_sequence

    seq = open_sequence(args.sequence, camera=args.camera)
    camera = seq.require_camera()
    if not camera.is_downward:
        raise VslamError(f"{args.sequence}: the camera has no camera_height; visual odometry needs a downward camera")
    config = VOConfig.from_dict(_overrides(args.set), base=VOConfig.preset(args.preset))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    fused = None
    if seq.odometry is not None and not args.no_fallback:
        gyro = seq.imu
        fused = fuse_wheel_gyro(seq.odometry.timestamps, seq.odometry.v, seq.odometry.omega,
                                None if gyro is None else gyro.timestamps, None if gyro is None else gyro.gyro_z,
                                seq.timestamps, FusionConfig.preset(args.fusion_preset))
        write_tum(out / "trajectory_fused.txt", seq.timestamps, fused.poses)

    n = len(seq)
    step = max(1, n // 20)

    def progress(est) -> None:
        if not args.quiet and (est.index % step == 0 or est.index == n - 1):
            print(f"\rframe {est.index + 1}/{n}", end="", file=sys.stderr, flush=True)

    traj = run_visual_odometry(camera, seq.timestamps, lambda i: seq.image(i, gray=True), config,
                               fallback=None if fused is None else (lambda i: fused.relative(i - 1, i)),
                               on_frame=progress)
    if not args.quiet:
        print(file=sys.stderr)
    write_tum(out / "trajectory_vo.txt", traj.timestamps, traj.poses)
    atomic_write_text(out / "odometry.csv", "\n".join(traj.csv_rows()) + "\n")

    counts = {s: sum(1 for x in traj.status if x == s) for s in VOStatus}
    vo_ms = float(np.median(traj.vo_seconds[1:]) * 1e3) if n > 1 else 0.0
    msg = (f"{n} frames: {counts[VOStatus.OK]} by vision, {counts[VOStatus.FALLBACK]} fallback, "
           f"{counts[VOStatus.LOST]} lost; {int(traj.is_keyframe.sum())} keyframes; VO step {vo_ms:.2f} ms/frame "
           f"(median); wrote {out / 'trajectory_vo.txt'} and {out / 'odometry.csv'}")
    gt = seq.groundtruth_planar()
    if gt is not None and np.all(np.isfinite(gt[[0, -1]])):
        from odometry.shared.poses import between

        g = between(gt[0], gt)
        dist = float(np.sum(np.hypot(*np.diff(g[:, :2][np.all(np.isfinite(g), 1)], axis=0).T)))
        if dist > 0:
            err = float(np.hypot(*(traj.poses[-1, :2] - g[-1, :2])))
            msg += f"; end-point error {err * 100:.1f} cm over {dist:.1f} m ({err / dist * 100:.2f} %)"
    print(msg)
    return 0
