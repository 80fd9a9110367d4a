"""`vslam loops SEQ --mode M --out DIR`: loop detection alone (compact descriptors), writes DIR/loops.csv.

Works on any image sequence (sequence directory, TUM/KITTI folder, image folder, video); see `vslam.app.loops`.
"""
from __future__ import annotations

import argparse
import sys

from vslam.cli.options import add_frame_and_out_options
from vslam.cli.progress import Progress

NAME = "loops"
HELP = "detect loops in an image sequence with compact descriptors (writes loops.csv)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", help="sequence directory, TUM RGB-D / KITTI folder, image folder or video")
    p.add_argument("--mode", type=int, default=4, choices=range(1, 7), metavar="{1..6}",
                   help="descriptor mode: 512 B, 1, 2, 4, 8, 16 kB (default 4)")
    p.add_argument("--out", required=True, help="output directory (loops.csv, summary.json)")
    p.add_argument("--model", help="loop model JSON from `vslam train-loops` (default: the shipped model)")
    p.add_argument("--threshold", type=float, help="accept local scores >= this instead of the model threshold")
    p.add_argument("--every", type=int, default=1, help="use every N-th frame as a keyframe (default 1)")
    p.add_argument("--shortlist", type=int, default=5, help="candidates verified per query (default 5)")
    p.add_argument("--exclude-recent", type=int, default=0,
                   help="never match the most recent N keyframes (default 0: time and footprint decide)")
    p.add_argument("--exclude-seconds", type=float, default=2.0,
                   help="never match keyframes taken less than S seconds before the query (default 2)")
    p.add_argument("--odometry", default="auto", metavar="{auto,wheel,vo,none,TUM_FILE}",
                   help="poses for the footprint exclusion and the motion check of loops: the sequence's wheel "
                        "odometry, our visual odometry, none, or a TUM trajectory (default auto: wheel if present, "
                        "else visual odometry for a downward camera)")
    p.add_argument("--appearance-only", action="store_true",
                   help="ignore odometry: exclude by time and count only, no motion check")
    p.add_argument("--gate-chi2", type=float, default=16.27,
                   help="motion check: Mahalanobis bound on (dx, dy, dtheta) (default 16.27, chi-square 3 dof 99.9%%)")
    p.add_argument("--confirmations", type=int, default=1,
                   help="consecutive keyframes that must agree before a loop is accepted (default 1)")
    p.add_argument("--geometry", choices=["auto", "floor", "general"], default="auto",
                   help="geometric model: floor = rotation+translation (downward camera), general = affine")
    p.add_argument("--camera", help="camera.yaml to use (image folders and videos)")
    p.add_argument("--fps", type=float, default=10.0, help="frame rate for image folders without timestamps")
    p.add_argument("--quiet", action="store_true")
    add_frame_and_out_options(p)


def run(a: argparse.Namespace) -> int:
    from vslam.app.loops import detect_sequence_loops  # on use: keeps `vslam --help` fast
    from vslam.pipeline.motion_gate import MotionGateParams

    bar = Progress(0, "loops", enabled=None if not a.quiet else False)
    res = detect_sequence_loops(a.sequence, a.out, mode=a.mode, model=a.model, threshold=a.threshold, every=a.every,
                                shortlist=a.shortlist, exclude_recent=a.exclude_recent,
                                confirmations=a.confirmations, geometry=a.geometry, camera=a.camera, fps=a.fps,
                                progress=bar.update, exclude_seconds=a.exclude_seconds, odometry=a.odometry,
                                appearance_only=a.appearance_only, gate=MotionGateParams(chi2=a.gate_chi2),
                                overwrite=a.overwrite, skip_bad_frames=a.skip_bad_frames)
    bar.close()
    for w in res.warnings[:5]:
        print(f"vslam loops: warning: skipped unreadable frame: {w}", file=sys.stderr)
    if not a.quiet:
        print(res.line())
    return 0
