"""Options several commands share, with one wording (the commands that read a sequence and write an --out folder)."""
from __future__ import annotations

import argparse


def add_frame_and_out_options(p: argparse.ArgumentParser, writes: str = "the files this command writes") -> None:
    """--skip-bad-frames and --overwrite, as `vslam run`, `vslam odometry` and `vslam loops` take them."""
    p.add_argument("--skip-bad-frames", action="store_true",
                   help="accept missing/corrupt images: warn, continue, flag the frame (default: a missing image "
                        "listed in frames.csv is an error)")
    p.add_argument("--overwrite", action="store_true",
                   help=f"reuse a non-empty --out folder, removing {writes} (refused otherwise)")
