"""`vslam odometry SEQ --out DIR`: downward visual odometry over a sequence (see `vslam.app.odometry`)."""
from __future__ import annotations

import argparse

from vslam.cli.options import add_frame_and_out_options
from vslam.cli.progress import Progress

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
    add_frame_and_out_options(p)


def run(args: argparse.Namespace) -> int:
    from vslam.app.odometry import parse_overrides, run_odometry  # on use: keeps `vslam --help` fast

    bar = Progress(0, label="vslam odometry", enabled=None if not args.quiet else False)
    res = run_odometry(args.sequence, args.out, camera=args.camera, preset=args.preset,
                       fusion_preset=args.fusion_preset, overrides=parse_overrides(args.set),
                       fallback=not args.no_fallback, progress=bar.update,
                       overwrite=args.overwrite, skip_bad_frames=args.skip_bad_frames)
    bar.close()
    print(res.summary())
    return 0
