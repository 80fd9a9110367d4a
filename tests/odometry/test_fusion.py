"""Wheel/gyro EKF: exact on noise-free input, bias/scale estimation and honest covariances on noisy input."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from odometry.fusion import FusionConfig, Interpolation, fuse_wheel_gyro
from odometry.shared.poses import between, compose, integrate, wrap_angle

WHEEL_DT, GYRO_DT, FRAME_DT = 0.02, 0.01, 0.1
# the streams below sample continuous rates on two different clocks: read them linearly
LIN = FusionConfig(interpolation=Interpolation.LINEAR)


def _rates(t):
    """A smooth S-shaped path: speed and yaw rate that both vary."""
    return 0.5 + 0.2 * np.sin(0.3 * t), 0.6 * np.sin(0.5 * t) + 0.1


def _truth(duration, query_t, step=1e-3):
    tf = np.arange(0.0, duration + 2 * step, step)
    v, w = _rates(tf + 0.5 * step)
    half = 0.5 * w * step  # each step as the chord of its arc: second-order accurate
    poses = integrate(np.column_stack([v * step * np.cos(half), v * step * np.sin(half), w * step]))
    return poses[np.round(query_t / step).astype(int)]


def _streams(duration, rng=None, bias=0.0, scale=0.0, cfg=FusionConfig()):
    tw = np.arange(0.0, duration, WHEEL_DT)
    tg = np.arange(0.003, duration, GYRO_DT)  # a different clock on purpose
    v, w = _rates(tw)
    _, wg = _rates(tg)
    w = w * (1.0 + scale)
    wg = wg + bias
    if rng is not None:
        v = v + rng.normal(0, cfg.wheel_v_sigma, len(v))
        w = w + rng.normal(0, cfg.wheel_omega_sigma, len(w))
        wg = wg + rng.normal(0, cfg.gyro_sigma, len(wg))
    return tw, v, w, tg, wg


def _err(est, ref):
    e = est - ref
    e[..., 2] = wrap_angle(e[..., 2])
    return e


@pytest.mark.parametrize("mode", ["both", "wheel_only", "gyro_and_speed"])
def test_noise_free_constant_rates_reproduce_the_exact_arc(mode):
    v0, w0 = 0.4, 0.25
    tw = np.arange(0.0, 12.0, 0.02)
    tg = np.arange(0.001, 12.0, 0.005)
    q = np.arange(0.0, 11.9, 1 / 30)
    f = fuse_wheel_gyro(tw, np.full(len(tw), v0), None if mode == "gyro_and_speed" else np.full(len(tw), w0),
                        None if mode == "wheel_only" else tg, None if mode == "wheel_only" else np.full(len(tg), w0),
                        q)
    # closed form: a circle of radius v/w starting at the origin heading +x
    th = w0 * (q - q[0])
    expect = np.column_stack([v0 / w0 * np.sin(th), v0 / w0 * (1 - np.cos(th)), wrap_angle(th)])
    assert np.abs(_err(f.poses, expect)).max() < 1e-9
    assert np.allclose(f.poses[0], 0.0) and f.covariances.shape == (len(q), 3, 3)
    assert np.all(np.diff([np.trace(c) for c in f.covariances]) >= -1e-15)  # dead reckoning only grows


def _arcs(v, w, dt):
    """Exact unicycle steps for rates held constant over dt."""
    th = w * dt
    small = np.abs(th) < 1e-12
    r = np.where(small, 0.0, v / np.where(small, 1.0, w))
    dx = np.where(small, v * dt, r * np.sin(th))
    dy = np.where(small, 0.0, r * (1 - np.cos(th)))
    return np.column_stack([dx, dy, th])


def test_noise_free_held_rates_reproduce_the_exact_integral():
    """The sequence-format convention (a sample holds until the next): exact to rounding, like the simulator."""
    t = np.arange(1000) * 0.01
    v, w = _rates(t)
    truth = integrate(_arcs(v[:-1], w[:-1], 0.01))
    q = t[::7]
    f = fuse_wheel_gyro(t, v, w, t, w, q)
    assert np.abs(_err(f.poses, truth[::7])).max() < 1e-9
    assert abs(f.bias[-1]) < 1e-12 and abs(f.wheel_scale[-1]) < 1e-12


def test_noise_free_linear_rates_match_a_fine_integral():
    q = np.arange(0.0, 20.0, FRAME_DT)
    tw, v, w, tg, wg = _streams(20.5)
    cfg = FusionConfig(interpolation=Interpolation.LINEAR)
    f = fuse_wheel_gyro(tw, v, w, tg, wg, q, cfg)
    assert np.abs(_err(f.poses, _truth(20.5, q))).max() < 2e-4  # interpolation error of 50 Hz rates only
    assert abs(f.bias[-1]) < 1e-6 and abs(f.wheel_scale[-1]) < 1e-5


def test_noisy_gyro_bias_and_wheel_scale_are_estimated_and_beat_dead_reckoning():
    rng = np.random.default_rng(7)
    duration = 40.0
    q = np.arange(0.0, duration - 0.5, FRAME_DT)
    bias, scale = 0.015, 0.04
    tw, v, w, tg, wg = _streams(duration, rng, bias=bias, scale=scale)
    truth = _truth(duration, q)
    fused = fuse_wheel_gyro(tw, v, w, tg, wg, q, LIN)
    wheel = fuse_wheel_gyro(tw, v, w, None, None, q, LIN)
    gyro_raw = fuse_wheel_gyro(tw, v, None, tg, wg, q, LIN)  # gyro + wheel speed, bias not observable

    assert abs(fused.bias[-1] - bias) < max(3 * fused.bias_sigma[-1], 1e-3)
    assert fused.bias_sigma[-1] < 0.2 * LIN.gyro_bias_sigma0
    assert abs(fused.wheel_scale[-1] - scale) < 0.01
    e_f, e_w, e_g = (_err(x.poses, truth) for x in (fused, wheel, gyro_raw))
    rms = lambda e, c: float(np.sqrt(np.mean(e[:, c] ** 2)))  # noqa: E731
    assert rms(e_f, 2) < 0.3 * rms(e_w, 2) and rms(e_f, 2) < 0.3 * rms(e_g, 2)
    pos = lambda e: float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, 1))))  # noqa: E731
    assert pos(e_f) < 0.5 * pos(e_w)
    # the final error is plausible under the reported covariance (chi2(3) at 99.9 %)
    e = e_f[-1]
    assert e @ np.linalg.solve(fused.covariances[-1], e) < 16.3


def test_covariances_are_consistent_monte_carlo():
    """Mean NEES of the final pose and of a 3 s relative motion is ~3 when the noise matches the model."""
    cfg = FusionConfig(slip_forward=0.0, slip_lateral=0.0, slip_heading=0.0, wheel_scale_walk=0.0,
                       gyro_bias_walk=0.0, speed_scale_sigma0=0.0, interpolation=Interpolation.LINEAR)
    duration = 10.0
    q = np.arange(0.0, 9.6, FRAME_DT)
    truth = _truth(duration, q)
    nees_abs, nees_rel = [], []
    for seed in range(25):
        rng = np.random.default_rng(seed)
        b, s = rng.normal(0, cfg.gyro_bias_sigma0), rng.normal(0, cfg.wheel_scale_sigma0)
        f = fuse_wheel_gyro(*_streams(duration, rng, bias=b, scale=s, cfg=cfg), q, cfg)
        e = _err(f.poses[-1], truth[-1])
        nees_abs.append(e @ np.linalg.solve(f.covariances[-1], e))
        d, c = f.relative(40, 70)
        e = _err(d, between(truth[40], truth[70]))
        nees_rel.append(e @ np.linalg.solve(c, e))
    # 25 samples of chi2(3): the mean has a standard deviation of ~0.5
    assert 1.5 < np.mean(nees_abs) < 5.0
    assert 1.5 < np.mean(nees_rel) < 5.0


def test_relative_motion_and_its_covariance():
    rng = np.random.default_rng(3)
    q = np.arange(0.0, 15.0, FRAME_DT)
    f = fuse_wheel_gyro(*_streams(15.5, rng), q, LIN)
    d, c = f.relative(100, 110)
    assert np.allclose(compose(f.poses[100], d), f.poses[110])
    # relative motion is much better known than the difference of two drifted absolute poses
    assert np.trace(c) < 0.5 * (np.trace(f.covariances[100]) + np.trace(f.covariances[110]))
    assert np.all(np.linalg.eigvalsh(c) > 0)
    # the reverse motion is the inverse, with the covariance propagated through the inverse's Jacobian
    d2, c2 = f.relative(110, 100)
    assert np.allclose(compose(d, d2), 0.0, atol=1e-12)
    cs, sn = np.cos(d[2]), np.sin(d[2])
    j = np.array([[-cs, -sn, sn * d[0] - cs * d[1]], [sn, -cs, cs * d[0] + sn * d[1]], [0, 0, -1]])
    assert np.allclose(c2, j @ c @ j.T, rtol=1e-6, atol=1e-15)
    d0, c0 = f.relative(5, 5)
    assert np.all(d0 == 0) and np.all(c0 == 0)
    with pytest.raises(IndexError):
        f.relative(0, len(q))
    # consecutive relative covariances grow with the interval
    assert np.trace(f.relative(100, 101)[1]) < np.trace(f.relative(100, 120)[1])


def test_a_sensor_gap_inflates_the_covariance_but_keeps_going():
    q = np.arange(0.0, 10.0, FRAME_DT)
    tw, v, w, tg, wg = _streams(10.5)
    full = fuse_wheel_gyro(tw, v, w, tg, wg, q, LIN)
    keep = (tw < 4.0) | (tw > 6.0)
    gap = fuse_wheel_gyro(tw[keep], v[keep], w[keep], tg, wg, q, LIN)
    assert np.all(np.isfinite(gap.poses))
    k = 65  # after the gap
    assert gap.covariances[k][0, 0] + gap.covariances[k][1, 1] > 10 * (full.covariances[k][0, 0]
                                                                       + full.covariances[k][1, 1])
    # the gyro still carries the heading through the gap
    assert np.abs(_err(gap.poses, _truth(10.5, q))[:, 2]).max() < 1e-3


def test_slip_spikes_do_not_corrupt_the_bias():
    rng = np.random.default_rng(11)
    q = np.arange(0.0, 30.0, FRAME_DT)
    tw, v, w, tg, wg = _streams(30.5, rng, bias=0.01)
    w = w.copy()
    spikes = rng.choice(len(w), 40, replace=False)
    w[spikes] += rng.choice([-1.0, 1.0], 40) * 2.0  # a wheel spinning on a slippery patch
    f = fuse_wheel_gyro(tw, v, w, tg, wg, q, LIN)
    assert abs(f.bias[-1] - 0.01) < 3e-3
    ungated = fuse_wheel_gyro(tw, v, w, tg, wg, q, dataclasses.replace(LIN, bias_gate=0.0))
    assert abs(f.bias[-1] - 0.01) < abs(ungated.bias[-1] - 0.01)


def test_bad_inputs_raise_clear_errors():
    tw, v, w, tg, wg = _streams(2.0)
    q = np.arange(0.0, 1.5, 0.1)
    with pytest.raises(ValueError, match="wheel omega"):
        fuse_wheel_gyro(tw, v, w[:-1], tg, wg, q)
    bad_t = tw.copy()
    bad_t[5] = bad_t[4]
    with pytest.raises(ValueError, match="wheel timestamps must increase strictly: sample 5"):
        fuse_wheel_gyro(bad_t, v, w, tg, wg, q)
    with pytest.raises(ValueError, match="no yaw-rate source"):
        fuse_wheel_gyro(tw, v, None, None, None, q)
    with pytest.raises(ValueError, match="wheel odometry speed is required"):
        fuse_wheel_gyro(None, None, None, tg, wg, q)
    nan_g = wg.copy()
    nan_g[3] = np.nan
    with pytest.raises(ValueError, match="gyro_z: non-finite value at sample 3"):
        fuse_wheel_gyro(tw, v, w, tg, nan_g, q)
    with pytest.raises(ValueError, match="query_t must be non-decreasing"):
        fuse_wheel_gyro(tw, v, w, tg, wg, q[::-1])
    with pytest.raises(ValueError, match="gyro_t and gyro_z"):
        fuse_wheel_gyro(tw, v, w, tg, None, q)


def test_repeated_query_times_and_config_presets():
    tw, v, w, tg, wg = _streams(3.0)
    q = np.array([0.0, 0.0, 0.5, 0.5, 1.0])
    f = fuse_wheel_gyro(tw, v, w, tg, wg, q, FusionConfig.preset("precise"))
    assert np.allclose(f.poses[0], f.poses[1]) and np.allclose(f.poses[2], f.poses[3])
    assert FusionConfig.from_dict({"gyro_sigma": 0.01}).gyro_sigma == 0.01
    with pytest.raises(ValueError, match="unknown FusionConfig field"):
        FusionConfig.from_dict({"gyro_noise": 0.01})
    with pytest.raises(ValueError, match="gyro_sigma must be >= 0"):
        FusionConfig(gyro_sigma=-1.0)
    with pytest.raises(ValueError, match="unknown fusion preset"):
        FusionConfig.preset("nope")
    assert FusionConfig.preset("slippery").slip_forward > FusionConfig().slip_forward
