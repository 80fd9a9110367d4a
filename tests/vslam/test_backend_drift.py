"""Large heading drift in the visual odometry: the back end keeps the pipeline's true loops and closes the map.

A gyro-like scale error on the VO heading increments (3 % of every turn: 11 degrees per lap of the simulated loop)
makes the odometry drift far from the revisited places, which is when loop closures matter. A back end that tests
loops against the drifted estimate (the old arrival gate) rejected exactly these loops (issue 14).
"""
from dataclasses import replace

import numpy as np
import pytest

from odometry.shared.poses import compose
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.pipeline.motion_gate import DriftModel
from vslam.sim import SimConfig, simulate

HEADING_SCALE_ERROR = 0.03


class HeadingDrift:
    """Wraps the pipeline's visual odometry: every heading increment is scaled by (1 + rate), the pose re-composed."""

    def __init__(self, vo, rate: float):
        self.vo, self.rate, self.pose = vo, rate, None

    def process(self, image, timestamp, fallback=None):
        est = self.vo.process(image, timestamp, fallback=fallback)
        delta = np.asarray(est.delta, float).copy()
        delta[2] *= 1.0 + self.rate
        self.pose = np.asarray(est.pose, float).copy() if self.pose is None else compose(self.pose, delta)
        return replace(est, delta=delta, pose=self.pose.copy())


class DriftingPipeline(Pipeline):
    """The pipeline with drifting visual odometry (`run` resets, so the wrap goes in `reset`)."""

    def reset(self, camera) -> None:
        super().reset(camera)
        self.vo = HeadingDrift(self.vo, HEADING_SCALE_ERROR)


@pytest.fixture(scope="module")
def drifted(tmp_path_factory):
    root = tmp_path_factory.mktemp("drift")
    simulate(SimConfig(length=6.0, laps=2, fps=15.0, speed=0.5, seed=4), root / "seq")
    seq = open_sequence(root / "seq")
    base = PipelineConfig()
    # this VO drifts 15x more than ours (vslam.pipeline.motion_gate.vo_drift), so it declares the generic drift model
    # (1 % of every turn, 1.5 sigma for 3 %): the gate must pass its true loops for the back end to judge them
    cfg = replace(base, recording=replace(base.recording, enabled=False),
                  loops=base.loops.replace(gate=base.loops.gate.replace(drift=DriftModel())))
    out = {}
    for incremental in (False, True):
        pipe = DriftingPipeline(replace(cfg, incremental=incremental))
        out[incremental] = (pipe.run(seq), pipe)
    return seq, out


def _ape(est: np.ndarray, gt: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((est[:, :2] - gt[:, :2]) ** 2, axis=1))))


@pytest.mark.parametrize("incremental", [False, True], ids=["batch", "isam2"])
def test_true_loops_kept_under_heading_drift(drifted, incremental):
    seq, out = drifted
    res, pipe = out[incremental]
    gt = seq.groundtruth_planar()
    gt = gt - gt[0] if gt is not None else None
    loops = [r for r in res.loops if r.accepted and r.loop_index is not None]
    assert len(loops) >= 3                                   # the second lap revisits the first
    kept = [r.inlier for r in loops]
    # >= 95 %: with 3 % biased odometry a single loop can end up far out (measured: batch keeps 48 of 49)
    assert kept.count(True) >= 0.95 * len(kept), f"back end rejected {kept.count(False)} of {len(kept)} true loops"
    vo_end = np.linalg.norm(res.poses_vo[-1, :2] - res.poses_vo[0, :2])
    slam_end = np.linalg.norm(res.poses_slam[-1, :2] - res.poses_slam[0, :2])
    assert vo_end > 0.2                                      # the drift is real ...
    assert slam_end < 0.25 * vo_end                          # ... and the loops close the map
    if gt is not None:
        assert _ape(res.poses_slam, gt) < 0.5 * _ape(res.poses_vo, gt)
