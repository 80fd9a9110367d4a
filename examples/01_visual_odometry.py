"""Visual odometry only: frame-to-frame motion from a downward camera, and how far it drifts from ground truth.

    python examples/01_visual_odometry.py                  # renders a short simulated sequence first
    python examples/01_visual_odometry.py SEQ              # any sequence with a downward camera.yaml

No wheel odometry, gyro, loops or pose graph: `run_visual_odometry` chains the motions it measures, so its error
grows with distance. The same thing on the command line: `vslam odometry SEQ --out DIR`.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import vslam
from odometry import VOStatus, between, run_visual_odometry
from vslam.sim import SimConfig, simulate


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sequence", nargs="?", help="sequence with a downward camera (default: simulate one)")
    p.add_argument("--frames", type=int, default=120, help="frames to simulate (default 120)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        # 1. The input: a given sequence, or a small simulated one (320x240 over carpet, with ground truth).
        path = Path(a.sequence) if a.sequence else Path(tmp) / "seq"
        if not a.sequence:
            simulate(SimConfig(width=320, height=240, focal=250.0, max_frames=a.frames, seed=1), path)
        seq = vslam.open_sequence(path)

        # 2. Visual odometry over every frame: images are decoded one at a time (grey is all VO needs).
        vo = run_visual_odometry(seq.require_camera(), seq.timestamps, lambda i: seq.image(i, gray=True))
        ok = sum(s == VOStatus.OK for s in vo.status)
        print(f"{len(vo)} frames, {ok} measured by vision, median {np.median(vo.vo_seconds) * 1e3:.1f} ms per frame")
        gt = seq.groundtruth_planar()

    # 3. Drift: both trajectories expressed in the frame of their first pose, compared without any alignment.
    if gt is None:
        print("no ground truth: final VO pose", np.round(vo.poses[-1], 3))
        return 0
    gt_rel = between(gt[0], gt)                    # ground truth relative to the start
    err = np.hypot(*(vo.poses[:, :2] - gt_rel[:, :2]).T)
    length = float(np.sum(np.hypot(*np.diff(gt[:, :2], axis=0).T)))
    print(f"path {length:.2f} m; position error: final {err[-1] * 100:.2f} cm, max {err.max() * 100:.2f} cm")
    print(f"drift {100 * err[-1] / max(length, 1e-9):.2f} % of the distance travelled")
    return 0


if __name__ == "__main__":
    sys.exit(main())
