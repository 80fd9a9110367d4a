"""Planar rigid fit: exact SVD solution, direction convention, RANSAC with outliers, covariance."""
from __future__ import annotations

import numpy as np
import pytest

from odometry.rigid import apply, kabsch_2d, ransac_rigid_2d, rigid_covariance
from odometry.shared.poses import compose, inverse, transform_points


@pytest.mark.parametrize("delta", [(0.013, -0.004, 0.021), (-1.5, 2.0, 2.9), (0.0, 0.0, -3.1), (1e-4, 0.0, 0.0)])
def test_kabsch_recovers_an_exact_motion_to_1e9(delta):
    rng = np.random.default_rng(0)
    src = rng.uniform(-0.3, 0.3, (50, 2))
    d = np.array(delta)
    est = kabsch_2d(src, apply(d, src))
    assert np.allclose(est, d, atol=1e-9, rtol=0)
    # weights do not change an exact solution; two points are enough
    assert np.allclose(kabsch_2d(src, apply(d, src), weights=rng.uniform(0.1, 1, 50)), d, atol=1e-9, rtol=0)
    assert np.allclose(kabsch_2d(src[:2], apply(d, src[:2])), d, atol=1e-9, rtol=0)


def test_kabsch_never_returns_a_reflection():
    rng = np.random.default_rng(1)
    src = rng.uniform(-1, 1, (30, 2))
    mirrored = src * [1, -1]  # the best orthogonal map is a reflection; a rotation must come out
    est = kabsch_2d(src, mirrored)
    assert np.all(np.isfinite(est))
    r = apply(est, src) - mirrored
    assert np.sum(r * r) > 1.0  # it cannot fit a mirror image


def test_direction_convention_matches_pose_composition():
    """Floor points seen in frame k-1 and frame k: the fit cur -> prev IS the robot motion (compose convention)."""
    rng = np.random.default_rng(2)
    world = rng.uniform(-1, 1, (40, 2))
    pose_prev = np.array([0.7, -0.2, 0.4])
    motion = np.array([0.05, 0.01, 0.03])
    pose_cur = compose(pose_prev, motion)
    in_prev = transform_points(inverse(pose_prev), world)
    in_cur = transform_points(inverse(pose_cur), world)
    est = kabsch_2d(in_cur, in_prev)
    assert np.allclose(est, motion, atol=1e-12)
    assert np.allclose(compose(pose_prev, est), pose_cur, atol=1e-12)


def test_ransac_with_50_percent_outliers():
    rng = np.random.default_rng(3)
    n = 200
    src = rng.uniform(-0.3, 0.3, (n, 2))
    d = np.array([0.02, -0.01, 0.05])
    dst = apply(d, src) + rng.normal(0, 2e-4, (n, 2))
    bad = rng.permutation(n)[: n // 2]
    dst[bad] = rng.uniform(-0.3, 0.3, (len(bad), 2))
    truth = np.ones(n, bool)
    truth[bad] = False
    fit = ransac_rigid_2d(src, dst, 1e-3, rng=np.random.default_rng(0))
    assert fit is not None
    assert np.abs(fit.delta[:2] - d[:2]).max() < 1e-4 and abs(fit.delta[2] - d[2]) < 5e-4
    assert np.sum(fit.inliers & truth) >= 0.97 * truth.sum()
    assert np.sum(fit.inliers & ~truth) <= 2
    # the estimate is within a few sigma of its own covariance
    e = fit.delta - d
    assert e @ np.linalg.solve(fit.covariance, e) < 16.3
    # deterministic for a given generator seed
    again = ransac_rigid_2d(src, dst, 1e-3, rng=np.random.default_rng(0))
    assert np.array_equal(again.delta, fit.delta) and np.array_equal(again.inliers, fit.inliers)


def test_covariance_matches_monte_carlo():
    rng = np.random.default_rng(4)
    src = rng.uniform(-0.3, 0.3, (60, 2)) + [0.2, 0.0]  # off-centre: translation and rotation correlate
    d = np.array([0.01, 0.0, 0.02])
    sigma = 3e-4
    ests = np.array([kabsch_2d(src, apply(d, src) + rng.normal(0, sigma, src.shape)) for _ in range(3000)])
    emp = np.cov(ests.T)
    model = rigid_covariance(src, d, sigma)
    assert np.allclose(np.diag(emp) / np.diag(model), 1.0, atol=0.12)
    corr = lambda c: c[0, 2] / np.sqrt(c[0, 0] * c[2, 2])  # noqa: E731
    assert abs(corr(emp) - corr(model)) < 0.05


def test_degenerate_inputs():
    rng = np.random.default_rng(5)
    assert ransac_rigid_2d(np.zeros((1, 2)), np.zeros((1, 2)), 1e-3, rng=rng) is None
    same = np.zeros((20, 2))
    assert ransac_rigid_2d(same, same, 1e-3, rng=rng) is None  # no usable pair of distinct points
    with pytest.raises(ValueError, match=">= 2 matched pairs"):
        kabsch_2d(np.zeros((1, 2)), np.zeros((1, 2)))
