"""Helpers of `vslam bench odometry --regimes`: planar ATE, frame subsampling, the naive ORB chain."""
import numpy as np

from odometry.shared.poses import compose, integrate
from vslam.bench.baseline_orb_chain import naive_orb_chain, planar_ate
from vslam.bench.odometry_regimes import subsample
from vslam.io import open_sequence
from vslam.sim import Effects, SimConfig, simulate


def test_planar_ate_ignores_a_rigid_transform_and_sees_an_error():
    gt = integrate(np.tile([0.1, 0.0, 0.05], (40, 1)))
    moved = np.array([compose([1.0, -2.0, 0.7], p) for p in gt])
    assert planar_ate(moved, gt) < 1e-9
    bent = moved.copy()
    bent[20:, 0] += 0.05
    assert 0.01 < planar_ate(bent, gt) < 0.05


def test_subsample_and_the_naive_chain(tmp_path):
    cfg = SimConfig(width=320, height=240, focal=250.0, length=1.0, fps=10.0, speed=0.3, effects=Effects.preset("none"))
    src = simulate(cfg, tmp_path / "full").path
    dst = subsample(src, tmp_path / "sub", 3)
    full, sub = open_sequence(src), open_sequence(dst)
    assert len(sub) == (len(full) + 2) // 3 and np.allclose(sub.timestamps, full.timestamps[::3])
    assert np.array_equal(sub.image(1, gray=True), full.image(3, gray=True))
    poses, tracked, _ = naive_orb_chain(sub, sub.require_camera())
    gt = sub.groundtruth_planar()
    assert tracked == len(sub) - 1
    # the naive chain works on this easy sequence: a real baseline, not a strawman
    assert planar_ate(poses, gt) < 0.02
