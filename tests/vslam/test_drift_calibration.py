"""`drift_factor`: the smallest width of the drift model that keeps every true relative pose of a run inside the
motion gate (how `motion_gate.VO_DRIFT_FACTOR` was measured)."""
import numpy as np

from odometry.shared.poses import between, wrap_angle
from vslam.pipeline.drift_calibration import drift_factor
from vslam.pipeline.motion_gate import ChainMotion, DriftModel, MotionGateParams


def rectangle_with_heading_error(scale_error: float) -> tuple[np.ndarray, np.ndarray]:
    """Two laps of a 2 m x 1 m rectangle (truth) and an odometry that scales every turn by 1 + scale_error."""
    true, odo = [np.zeros(3)], [np.zeros(3)]
    for _ in range(2):
        for length in (2.0, 1.0, 2.0, 1.0):
            for _ in range(10):
                for path, k in ((true, 0.0), (odo, scale_error)):
                    x, y, th = path[-1]
                    path.append(np.array([x + length / 10 * np.cos(th), y + length / 10 * np.sin(th), th]))
            true[-1][2] += np.pi / 2
            odo[-1][2] += np.pi / 2 * (1 + scale_error)
    return np.array(odo), np.array(true)


def worst(poses, truth, k):
    d = DriftModel()
    chain = ChainMotion(poses, d.replace(trans_fraction=k * d.trans_fraction, turn_fraction=k * d.turn_fraction,
                                         heading_rad_per_height=k * d.heading_rad_per_height))
    out = 0.0
    for a in range(len(poses)):
        for b in range(a + 1, len(poses)):
            r = between(truth[a], truth[b]) - between(poses[a], poses[b])
            r[2] = wrap_angle(r[2])
            out = max(out, float(r @ np.linalg.solve(chain(a, b)[1], r)))
    return out


def test_the_factor_is_the_narrowest_gate_that_passes_every_true_pose():
    poses, truth = rectangle_with_heading_error(0.005)
    k = drift_factor(poses, truth, height=1.0, min_path_heights=0.0)
    chi2 = MotionGateParams().chi2
    assert 0.0 < k < 1.0
    assert worst(poses, truth, k) <= chi2 * (1 + 1e-6)
    assert worst(poses, truth, 0.9 * k) > chi2
    # a worse odometry needs a wider gate
    assert drift_factor(*rectangle_with_heading_error(0.02), height=1.0, min_path_heights=0.0) > k


def test_an_exact_odometry_needs_no_drift_and_a_too_short_run_gives_no_factor():
    _, truth = rectangle_with_heading_error(0.0)
    assert drift_factor(truth, truth, height=1.0) <= 1e-3
    assert drift_factor(truth[:3], truth[:3], height=1.0, min_path_heights=100.0) == 0.0
