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


def run(a: argparse.Namespace) -> int:
    from vslam.app.info import describe_sequence  # on use: keeps `vslam --help` fast (see vslam.cli.main)

    print(describe_sequence(a.sequence, camera=a.camera, fps=a.fps, decode=a.decode))
    print("valid      yes")
    return 0
