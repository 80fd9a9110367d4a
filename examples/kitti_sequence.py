"""Real data through the public-format readers: a KITTI odometry sequence (or a TUM RGB-D folder).

    python examples/kitti_sequence.py [PATH_TO_KITTI_OR_TUM_FOLDER] [WORKDIR]      # default WORKDIR: ./kitti_example

Default input: the KITTI 06 snippet in ../shared/data/places/kitti_snippets (51 real frames, forward camera).
The downward-camera parts (visual odometry on the floor, footprint loops) do not apply to a forward camera;
what does: reading and validating the format, converting it to a sequence directory, compact descriptors and
loop detection on any camera (`vslam loops`), and trajectory evaluation against the ground truth.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

from loops.cdvs import decode, encode, match
from odometry.shared.tum import tum_to_se3_matrices
from vslam.evaluation import evaluate
from vslam.io import open_sequence, write_sequence
from vslam.paths import shared_data_dir


def vslam_command(*args: str) -> bool:
    """Run a `vslam` command in a child process; False (and a message) when it fails."""
    sys.stdout.flush()      # our own lines first, then the child's
    done = subprocess.run([sys.executable, "-m", "vslam", *args])
    if done.returncode != 0:
        print(f"vslam {args[0]} failed with exit code {done.returncode}", file=sys.stderr)
    return done.returncode == 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("source", nargs="?", help="KITTI odometry folder (image_0/ + calib.txt [+ times.txt, poses.txt]) "
                                             "or TUM RGB-D folder (default: the KITTI 06 snippet of the shared data)")
    p.add_argument("workdir", nargs="?", default="kitti_example", help="output folder (default ./kitti_example)")
    a = p.parse_args(argv)
    data = shared_data_dir()
    default = None if data is None else data / "places" / "kitti_snippets" / "KITTI_sequence_1_kitti06_f0000-0050"
    src = Path(a.source) if a.source else default
    if src is None or not src.exists():
        print(f"{src or 'no input given'}: give a KITTI odometry or TUM RGB-D folder", file=sys.stderr)
        return 2
    work = Path(a.workdir)
    work.mkdir(parents=True, exist_ok=True)

    # 1. Read it (format detected from the folder layout) and validate it: `vslam info` prints a summary.
    seq = open_sequence(src)
    if not vslam_command("info", str(src)):
        return 1

    # 2. Convert to the toolkit's sequence directory (images copied byte for byte, ground truth as TUM).
    converted = write_sequence(seq, work / "sequence", overwrite=True)
    print(f"\nwrote {converted}; `vslam info {converted}` validates it")

    # 3. Compact descriptors on a forward camera: sizes per mode, and how similarity falls off along the drive.
    first = seq.image(0, gray=True)
    for mode in (1, 4, 6):
        print(f"mode {mode}: {len(encode(first, mode))} bytes")
    d = [decode(encode(seq.image(i, gray=True), 4)) for i in range(0, len(seq), 5)]
    local = [match(d[0], x).local_score for x in d]
    print("local score of frame 0 against frames 0, 5, 10, ...:", " ".join(f"{s:.0f}" for s in local))

    # 4. Loop detection alone on the sequence (no odometry, calibration or camera height needed).
    if not vslam_command("loops", str(converted), "--mode", "4", "--out", str(work / "loops"), "--quiet"):
        return 1
    print(f"loop candidates: {work / 'loops' / 'loops.csv'} (the KITTI 06 snippet drives straight: no true loop)")

    # 5. Evaluation against the ground truth: here a dead-reckoning guess (constant velocity from the first
    #    second) stands in for an estimate, to show ATE / RPE with evo's conventions.
    if seq.groundtruth is not None:
        gt = tum_to_se3_matrices(seq.groundtruth.poses)
        est = gt.copy()
        step = gt[min(10, len(gt) - 1), :3, 3] / min(10, len(gt) - 1)
        est[:, :3, 3] = np.arange(len(gt))[:, None] * step
        rep = evaluate(seq.groundtruth.timestamps, gt, seq.groundtruth.timestamps, est, "se3")
        print(f"constant-velocity guess vs ground truth: ATE {rep.ape['rmse']:.2f} m RMSE over {rep.path_length:.0f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
