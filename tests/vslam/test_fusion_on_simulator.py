"""The wheel/gyro EKF against the simulator's sensor streams: exact with perfect sensors, better than dead
reckoning with the default sensor errors (scale errors, slip, gyro bias and its random walk)."""
from __future__ import annotations

import numpy as np

from odometry.fusion import fuse_wheel_gyro
from odometry.shared.poses import between, wrap_angle
from vslam.sim import SensorNoise, SimConfig, plan_motion
from vslam.sim.randomness import keyed_rng
from vslam.sim.sensors import gyro_measurements, wheel_measurements


def _streams(noise: SensorNoise, seed: int = 4):
    cfg = SimConfig(trajectory="figure8", length=30.0, seed=seed)
    controls = plan_motion(cfg)
    rng = keyed_rng(seed, 7)
    wt, wv, ww = wheel_measurements(controls.t, controls.v, controls.omega, noise, rng)
    gt_, gz = gyro_measurements(controls.t, controls.omega, noise, rng)
    frames = np.arange(0.0, float(controls.t[-1]) - 0.1, 0.05)
    return (wt, wv, ww, gt_, gz), frames, controls.pose_at(frames)


def test_perfect_sensors_reproduce_the_simulated_ground_truth():
    streams, frames, truth = _streams(SensorNoise.preset("none"))
    fused = fuse_wheel_gyro(*streams, frames)
    err = fused.poses - between(truth[0], truth)
    err[:, 2] = wrap_angle(err[:, 2])
    assert np.abs(err).max() < 1e-9


def test_realistic_sensors_fusion_beats_wheel_only_and_estimates_the_bias():
    noise = SensorNoise()
    streams, frames, truth = _streams(noise)
    wt, wv, ww, gt_, gz = streams
    g = between(truth[0], truth)
    fused = fuse_wheel_gyro(wt, wv, ww, gt_, gz, frames)
    wheel = fuse_wheel_gyro(wt, wv, ww, None, None, frames)
    head = lambda f: np.sqrt(np.mean(wrap_angle(f.poses[:, 2] - g[:, 2]) ** 2))  # noqa: E731
    assert head(fused) < 0.5 * head(wheel)
    # the bias wanders from its initial value by a random walk of walk * sqrt(duration)
    wander = noise.gyro_bias_walk * np.sqrt(frames[-1])
    assert abs(fused.bias[-1] - noise.gyro_bias) < 3 * np.hypot(fused.bias_sigma[-1], wander)
    # the reported heading uncertainty covers the actual error at the end
    e = wrap_angle(fused.poses[-1, 2] - g[-1, 2])
    assert abs(e) < 3 * np.sqrt(fused.covariances[-1][2, 2])
