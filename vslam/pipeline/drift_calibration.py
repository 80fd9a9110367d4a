"""How wide must the motion gate's drift model be for a VO? The factor behind `motion_gate.VO_DRIFT_FACTOR`.

For a VO trajectory and its ground truth, the smallest factor k of the generic `DriftModel` (all three rates scaled
by k) with which every true relative pose between two frames more than `min_path_heights` camera heights of path
apart lies inside the gate (Mahalanobis distance squared <= chi2 against the VO's relative pose and the model's
covariance). A gate that wide passes every true loop of that run; anything wider only admits look-alikes.

    python -m vslam.pipeline.drift_calibration SEQ [SEQ ...]     # our VO on each sequence, then its factor
"""
from __future__ import annotations

import argparse
import sys

import numpy as np

from odometry.shared.poses import between, wrap_angle
from vslam.pipeline.motion_gate import ChainMotion, DriftModel, MotionGateParams


def drift_factor(poses: np.ndarray, truth: np.ndarray, height: float = 1.0, drift: DriftModel | None = None,
                 chi2: float | None = None, every: int = 1, min_path_heights: float = 2.0) -> float:
    """The smallest factor of `drift` (default: the generic model) that keeps every true relative pose inside the
    gate; 0 when no pair of frames is far enough apart, inf when even the full model is too narrow. `poses`,
    `truth` (N, 3) planar poses (x, y, theta) of the same frames; `every`: use every n-th frame (speed)."""
    drift = drift or DriftModel()
    chi2 = MotionGateParams().chi2 if chi2 is None else float(chi2)
    idx = np.arange(0, len(poses), max(1, int(every)))
    p, g = np.asarray(poses, float)[idx], np.asarray(truth, float)[idx]
    path = np.r_[0.0, np.cumsum(np.hypot(*np.diff(g[:, :2], axis=0).T))]
    pairs = [(a, b) for a in range(len(idx)) for b in range(a + 1, len(idx))
             if path[b] - path[a] > min_path_heights * height]
    if not pairs:
        return 0.0
    errors = []
    for a, b in pairs:
        r = between(g[a], g[b]) - between(p[a], p[b])
        r[2] = wrap_angle(r[2])
        errors.append(r)

    def worst(k: float) -> float:
        chain = ChainMotion(p, drift.scaled(k), height=height)
        return max(float(r @ np.linalg.solve(chain(a, b)[1], r)) for (a, b), r in zip(pairs, errors))

    lo, hi = 1e-4, 1.0
    if worst(hi) > chi2:
        return float("inf")
    for _ in range(30):     # bisection on a log scale: the worst distance falls as k grows
        mid = float(np.sqrt(lo * hi))
        if worst(mid) <= chi2:
            hi = mid
        else:
            lo = mid
    return hi


def main(argv: list[str] | None = None) -> int:
    from vslam.io import open_sequence
    from vslam.pipeline.config import PipelineConfig
    from vslam.pipeline.pipeline import Pipeline

    ap = argparse.ArgumentParser(prog="python -m vslam.pipeline.drift_calibration", description=__doc__.split("\n")[0])
    ap.add_argument("sequences", nargs="+")
    ap.add_argument("--every", type=int, default=0, help="use every n-th frame (default: 4 above 100 frames, else 1)")
    args = ap.parse_args(argv)
    for s in args.sequences:
        seq = open_sequence(s)
        est = Pipeline(PipelineConfig()).odometry(seq)
        poses = np.array([e.pose for e in est])
        truth = seq.groundtruth_planar()[:len(poses)]
        ok = ~np.isnan(truth[:, 0])
        every = args.every or (4 if ok.sum() > 100 else 1)
        k = drift_factor(poses[ok], truth[ok], seq.require_camera().camera_height, every=every)
        print(f"{s}: drift factor {k:.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
