"""Real data through the public-format readers: a KITTI odometry sequence (or a TUM RGB-D folder).

    python examples/kitti_sequence.py [PATH_TO_KITTI_OR_TUM_FOLDER] [WORKDIR]

Default input: the KITTI 06 snippet in ../shared/data/places/kitti_snippets (51 real frames, forward camera).
The downward-camera parts (visual odometry on the floor, footprint loops) do not apply to a forward camera;
what does: reading and validating the format, converting it to a sequence directory, compact descriptors and
loop detection on any camera (`vslam loops`), and trajectory evaluation against the ground truth.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from loops.cdvs import decode, encode, match
from odometry.shared.tum import tum_to_se3_matrices
from vslam.app.info import sequence_summary
from vslam.cli.main import main as vslam_cli
from vslam.evaluation import evaluate
from vslam.io import open_sequence, write_sequence
from vslam.paths import shared_data_dir

data = shared_data_dir()
default = None if data is None else data / "places" / "kitti_snippets" / "KITTI_sequence_1_kitti06_f0000-0050"
src = Path(sys.argv[1]) if len(sys.argv) > 1 else default
if src is None or not src.exists():
    sys.exit("give a KITTI odometry folder (image_0/ + calib.txt [+ times.txt, poses]) or a TUM RGB-D folder")
work = Path(sys.argv[2] if len(sys.argv) > 2 else "kitti_example")
work.mkdir(parents=True, exist_ok=True)

# 1. Read it (format detected from the folder layout) and validate it, as `vslam info` does.
seq = open_sequence(src)
print(sequence_summary(seq))

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
vslam_cli(["loops", str(converted), "--mode", "4", "--out", str(work / "loops"), "--quiet"])
print(f"loop candidates: {work / 'loops' / 'loops.csv'} (a 51-frame straight drive has no true loop)")

# 5. Evaluation against the ground truth: here a dead-reckoning guess (constant velocity from the first
#    second) stands in for an estimate, to show ATE / RPE with evo's conventions.
if seq.groundtruth is not None:
    gt = tum_to_se3_matrices(seq.groundtruth.poses)
    est = gt.copy()
    step = gt[min(10, len(gt) - 1), :3, 3] / min(10, len(gt) - 1)
    est[:, :3, 3] = np.arange(len(gt))[:, None] * step
    rep = evaluate(seq.groundtruth.timestamps, gt, seq.groundtruth.timestamps, est, "se3")
    print(f"constant-velocity guess vs ground truth: ATE {rep.ape['rmse']:.2f} m RMSE over {rep.path_length:.0f} m")
