"""Planar motion refined together with the momentary camera tilt and height of both frames.

A robot pitches, rolls and bounces a little as it drives (suspension, floor unevenness, accelerations). A tilt
of tau shifts the whole floor footprint by about camera_height * tau: 0.004 rad at 0.5 m is 2 mm, the same
as a translation, so a purely planar fit turns every wobble into odometry error. The tilt also changes the
perspective of the view (points far from the image centre move more), and that part is visible: the motion
between two views of the floor plane is a plane-induced homography with 8 degrees of freedom, which here are
the planar motion (3), the tilt of each frame (2 + 2) and the height ratio (1).

`refine_planar_tilt` starts from the rigid (Kabsch) solution on the RANSAC inliers and runs Gauss-Newton on

    r_i = R(dtheta) P_cur(x_cur_i; tilt_cur, h (1 + s)) + t - P_ref(x_ref_i; tilt_ref, h)

with zero-mean Gaussian priors on the tilts (tilt_sigma) and on s (height_sigma / h), so the estimate stays
well-posed when the motion is too small to see perspective. The covariance of (dx, dy, dtheta) is the
(dx, dy, dtheta) block of the inverse of the whitened normal matrix: it includes what the tilts leave unknown.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from odometry.shared.camera import CameraModel

_EPS = 1e-6  # finite-difference step for the tilt and height derivatives (rad, relative)


@dataclass
class TiltFit:
    """Refined motion; `params` = dx, dy, dtheta, roll_ref, pitch_ref, roll_cur, pitch_cur, s (height ratio - 1)."""

    delta: np.ndarray
    covariance: np.ndarray
    params: np.ndarray
    sigma: float
    rms: float
    iterations: int
    height_variance: float = 0.0  # marginal variance of s (the tilts unknown): how well the data fix the height
    # d s / d (tilt prior means) (roll_ref, pitch_ref, roll_cur, pitch_cur): how much of a tilt the data leave to
    # the priors passes into the height ratio. height_variance holds sum(gain^2) tilt_sigma^2 for tilts independent
    # between the two frames; a wobble shared by them (and by the next link) couples more (odometry.height)
    height_tilt_gain: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    tilt_variance: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # marginal variances of params[3:7]
    height_variance_data: float = 0.0  # height_variance less the tilt priors' part (what the image noise leaves)


def _floor(camera: CameraModel, xn: np.ndarray, heights: np.ndarray, tilts: np.ndarray) -> np.ndarray:
    base = np.asarray(camera.tilt)
    return camera.rays_to_floor_batch(xn, heights, np.asarray(tilts) + base)


def refine_planar_tilt(camera: CameraModel, xn_ref: np.ndarray, xn_cur: np.ndarray, delta0: np.ndarray,
                       tilt_sigma: float, height_sigma: float, sigma_floor: float, iterations: int = 2,
                       h_ref: float | None = None, s_prior: float = 0.0,
                       weights: np.ndarray | None = None,
                       tilt_prior: np.ndarray | None = None) -> TiltFit | None:
    """Gauss-Newton refinement of the planar motion ref -> cur with both frames' tilt and the height ratio.

    Args:
        camera: the downward camera (nominal height and any calibrated tilt; estimated tilts add to it).
        xn_ref, xn_cur: undistorted normalised coordinates (N, 2) of matched inlier points.
        delta0: (3,) starting motion (the rigid fit): P_ref ≈ R P_cur + t.
        tilt_sigma: prior standard deviation of each frame's roll and pitch (rad); 0 fixes them at 0.
        height_sigma: prior standard deviation of the height difference (m); 0 fixes it.
        sigma_floor: lower bound of the per-axis residual standard deviation (m) used for the covariance.
        iterations: Gauss-Newton steps (the problem is nearly linear: 2-3 suffice).
        h_ref: the reference frame's camera height (default: the camera's nominal height).
        s_prior: prior mean of s = h_cur / h_ref - 1 (e.g. pulling the current height towards the nominal one).
        weights: optional (N, 2, 2) information shape of each residual in floor axes (e.g.
            `odometry.tracking.aperture_weights`); None weighs every axis of every point alike.
        tilt_prior: prior means (4,) of roll_ref, pitch_ref, roll_cur, pitch_cur (rad; None: all 0), e.g. the
            tilts estimated for the same frames before: the tilt is slow, and a zero mean biases the height ratio.

    Returns None with fewer than 8 points.
    """
    xn_ref = np.asarray(xn_ref, dtype=np.float64).reshape(-1, 2)
    xn_cur = np.asarray(xn_cur, dtype=np.float64).reshape(-1, 2)
    n = len(xn_ref)
    if n < 8 or len(xn_cur) != n:
        return None
    h = float(camera.camera_height if h_ref is None else h_ref)
    q = np.zeros(8)
    q[:3] = delta0
    mu = np.zeros(8)
    mu[7] = s_prior
    if tilt_prior is not None:
        mu[3:7] = tilt_prior
        q[3:7] = tilt_prior
    # prior precisions (a zero sigma pins the parameter with a very stiff prior)
    prec = np.zeros(8)
    prec[3:7] = 1.0 / max(tilt_sigma, 1e-9) ** 2
    prec[7] = 1.0 / max(height_sigma / h, 1e-9) ** 2
    e = _EPS
    wl = None if weights is None else np.linalg.cholesky(np.asarray(weights, float)).transpose(0, 2, 1)
    sigma2 = max(sigma_floor, 1e-12) ** 2
    it = 0
    a_step = np.diag(prec)
    for it in range(1, iterations + 1):
        rk, pk, rc, pc, s = q[3:]
        pr = _floor(camera, xn_ref, [h, h, h], [(rk, pk), (rk + e, pk), (rk, pk + e)])
        pcur = _floor(camera, xn_cur, [h * (1 + s)] * 3 + [h * (1 + s + e)],
                      [(rc, pc), (rc + e, pc), (rc, pc + e), (rc, pc)])
        c, sn = math.cos(q[2]), math.sin(q[2])
        rot = np.array([[c, -sn], [sn, c]])
        rp = pcur[0] @ rot.T
        res = rp + q[:2] - pr[0]                                   # (N, 2)
        jac = np.empty((n, 2, 8))
        jac[:, :, 0] = [1.0, 0.0]
        jac[:, :, 1] = [0.0, 1.0]
        jac[:, 0, 2], jac[:, 1, 2] = -rp[:, 1], rp[:, 0]
        jac[:, :, 3] = -(pr[1] - pr[0]) / e
        jac[:, :, 4] = -(pr[2] - pr[0]) / e
        jac[:, :, 5] = ((pcur[1] - pcur[0]) / e) @ rot.T
        jac[:, :, 6] = ((pcur[2] - pcur[0]) / e) @ rot.T
        jac[:, :, 7] = ((pcur[3] - pcur[0]) / e) @ rot.T
        if wl is not None:   # whiten: r^T W r = |L^T r|^2
            res = np.einsum("nij,nj->ni", wl, res)
            jac = np.einsum("nij,njk->nik", wl, jac)
        jf = jac.reshape(-1, 8)
        rf = res.reshape(-1)
        if it == 1:
            # measurement noise from the rigid start: tilt effects only lower it, so this is conservative
            sigma2 = max(float(rf @ rf) / max(2 * n - 3, 1), sigma2)
        a = jf.T @ jf / sigma2 + np.diag(prec)
        g = jf.T @ rf / sigma2 + prec * (q - mu)
        a_step = a
        try:
            step = np.linalg.solve(a, -g)
        except np.linalg.LinAlgError:
            return None
        q = q + step
        if np.max(np.abs(step[:3])) < 1e-10:
            break
    # final residuals and covariance at the solution
    rk, pk, rc, pc, s = q[3:]
    pr = _floor(camera, xn_ref, [h], [(rk, pk)])[0]
    pcur = _floor(camera, xn_cur, [h * (1 + s)], [(rc, pc)])[0]
    c, sn = math.cos(q[2]), math.sin(q[2])
    res = pcur @ np.array([[c, -sn], [sn, c]]).T + q[:2] - pr
    rms = math.sqrt(float((res * res).sum()) / n)   # reported in metres, unweighted
    if wl is not None:
        res = np.einsum("nij,nj->ni", wl, res)
    rss = float((res * res).sum())
    sigma = max(math.sqrt(rss / max(2 * n - 8, 1)), sigma_floor)
    a = jf.T @ jf / sigma ** 2 + np.diag(prec)
    try:
        cov_full = np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return None
    cov = 0.5 * (cov_full[:3, :3] + cov_full[:3, :3].T)
    # the estimate moves by A^-1 P per unit of prior mean (row 7, tilt columns), A the normal matrix of the
    # Gauss-Newton steps: weighted by the rigid start's noise, not by the final residuals as the covariance is
    try:
        gain = np.linalg.solve(a_step, np.eye(8)[7])[3:7] * prec[3:7]
    except np.linalg.LinAlgError:
        gain = np.zeros(4)
    return TiltFit(delta=q[:3].copy(), covariance=cov, params=q, sigma=sigma, rms=rms,
                   iterations=it, height_variance=float(cov_full[7, 7]),
                   height_tilt_gain=tuple(float(g) for g in gain),
                   tilt_variance=tuple(float(v) for v in np.diag(cov_full)[3:7]),
                   height_variance_data=float(cov_full[7, 7] - np.sum(cov_full[7, 3:7] ** 2 * prec[3:7])))
