"""Tilt-aware refinement: a wobbling camera's planar motion is recovered where a rigid fit is off by millimetres."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from odometry.rigid import kabsch_2d
from odometry.shared.camera import CameraModel
from odometry.shared.poses import inverse, transform_points
from odometry.tilt_refine import refine_planar_tilt

CAM = CameraModel(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5,
                  distortion=(-0.04, 0.01, 0.0, 0.0, 0.0), camera_height=0.5)


def _views(delta, tilt_ref, tilt_cur, h_ref, h_cur, n=150, seed=0, noise_px=0.0):
    """Normalised coordinates of the same floor points seen by two wobbling cameras, and what a planar model
    that ignores the wobble back-projects them to."""
    rng = np.random.default_rng(seed)
    ref_cam = replace(CAM, camera_height=h_ref, tilt=tilt_ref)
    cur_cam = replace(CAM, camera_height=h_cur, tilt=tilt_cur)
    # floor points visible in both views
    uv = np.column_stack([rng.uniform(40, 600, 4 * n), rng.uniform(40, 440, 4 * n)])
    floor_ref = ref_cam.pixel_to_floor(uv)
    floor_cur = transform_points(inverse(delta), floor_ref)
    uv_cur = cur_cam.floor_to_pixel(floor_cur)
    ok = (uv_cur[:, 0] > 5) & (uv_cur[:, 0] < 635) & (uv_cur[:, 1] > 5) & (uv_cur[:, 1] < 475)
    uv, uv_cur = uv[ok][:n], uv_cur[ok][:n]
    uv = uv + rng.normal(0, noise_px, uv.shape)
    uv_cur = uv_cur + rng.normal(0, noise_px, uv_cur.shape)
    return CAM.normalize(uv), CAM.normalize(uv_cur)


def test_rays_to_floor_batch_matches_the_camera_model():
    rng = np.random.default_rng(1)
    xn = rng.uniform(-0.6, 0.6, (30, 2))
    cam = CameraModel(640, 480, 500, 500, 319.5, 239.5, camera_height=0.5, mount=(0.1, -0.05, 0.4))
    tilts = np.array([(0.0, 0.0), (0.004, -0.003), (-0.02, 0.01)])
    heights = np.array([0.5, 0.49, 0.52])
    batch = cam.rays_to_floor_batch(xn, heights, tilts)
    for k in range(3):
        assert np.allclose(batch[k], replace(cam, camera_height=heights[k], tilt=tuple(tilts[k])).rays_to_floor(xn), atol=1e-14)


def test_refinement_removes_the_wobble_error():
    delta = np.array([0.12, 0.03, 0.08])
    xr, xc = _views(delta, (0.003, -0.002), (-0.002, 0.004), 0.5, 0.5015)
    rigid = kabsch_2d(CAM.rays_to_floor(xc), CAM.rays_to_floor(xr))
    rigid_err = np.hypot(*(rigid[:2] - delta[:2]))
    assert rigid_err > 1e-3  # the planar model is off by millimetres
    fit = refine_planar_tilt(CAM, xr, xc, rigid, tilt_sigma=0.005, height_sigma=0.003, sigma_floor=1e-6,
                             iterations=4)
    assert np.hypot(*(fit.delta[:2] - delta[:2])) < 0.02 * rigid_err
    assert abs(fit.delta[2] - delta[2]) < 1e-4
    # the estimated tilts are those of the two cameras
    assert np.allclose(fit.params[3:7], [0.003, -0.002, -0.002, 0.004], atol=3e-4)


def test_refinement_is_harmless_without_wobble_and_its_covariance_is_consistent():
    delta = np.array([0.08, -0.02, -0.05])
    nees = []
    for seed in range(30):
        xr, xc = _views(delta, (0.0, 0.0), (0.0, 0.0), 0.5, 0.5, seed=seed, noise_px=0.1)
        rigid = kabsch_2d(CAM.rays_to_floor(xc), CAM.rays_to_floor(xr))
        fit = refine_planar_tilt(CAM, xr, xc, rigid, tilt_sigma=0.003, height_sigma=0.002, sigma_floor=1e-5)
        e = fit.delta - delta
        assert np.hypot(*e[:2]) < 5e-4
        nees.append(e @ np.linalg.solve(fit.covariance, e))
    assert 1.0 < np.mean(nees) < 6.0  # mean of chi2(3) is 3; the tilt priors make it a little conservative


def test_too_few_points():
    xr = np.zeros((5, 2))
    assert refine_planar_tilt(CAM, xr, xr, np.zeros(3), 0.003, 0.002, 1e-5) is None


def test_a_tilt_prior_at_the_frames_tilts_removes_the_height_ratio_bias_of_a_common_pitch():
    # both frames pitched alike (a slow wobble) and the overlap off the image centre: with zero-mean tilt priors the
    # unresolved tilt passes into the height ratio; the frames' own tilts as prior means (carry_tilt) remove it
    delta = np.array([0.12, 0.0, 0.0])
    tilt = (0.0, 0.004)
    err_zero, err_carried = [], []
    for seed in range(10):
        xr, xc = _views(delta, tilt, tilt, 0.5, 0.5, seed=seed, noise_px=0.1)
        rigid = kabsch_2d(CAM.rays_to_floor(xc), CAM.rays_to_floor(xr))
        zero = refine_planar_tilt(CAM, xr, xc, rigid, tilt_sigma=0.003, height_sigma=0.002, sigma_floor=1e-5)
        carried = refine_planar_tilt(CAM, xr, xc, rigid, tilt_sigma=0.003, height_sigma=0.002, sigma_floor=1e-5,
                                     tilt_prior=np.array([*tilt, *tilt]))
        err_zero.append(zero.params[7])
        err_carried.append(carried.params[7])
    assert abs(np.mean(err_zero)) > 2e-4           # a biased height link (0.02 % and more)
    assert abs(np.mean(err_carried)) < 0.3 * abs(np.mean(err_zero))


def test_the_height_tilt_gain_predicts_the_height_ratio_bias_of_a_common_pitch():
    # the refinement's d s / d (tilt prior means) says how much of a tilt it leaves to the priors passes into the
    # height ratio: a common pitch the zero-mean priors do not see biases s by about -gain . tilt
    delta = np.array([0.12, 0.0, 0.0])
    tilt = (0.0, 0.004)
    for seed in range(3):
        xr, xc = _views(delta, tilt, tilt, 0.5, 0.5, seed=seed, noise_px=0.0)
        rigid = kabsch_2d(CAM.rays_to_floor(xc), CAM.rays_to_floor(xr))
        fit = refine_planar_tilt(CAM, xr, xc, rigid, tilt_sigma=0.003, height_sigma=0.002, sigma_floor=1e-5,
                                 iterations=4)
        predicted = -float(np.dot(fit.height_tilt_gain, [*tilt, *tilt]))
        assert abs(fit.params[7]) > 1e-4             # a biased height link (0.01 % and more)
        assert abs(fit.params[7] - predicted) < 0.25 * abs(fit.params[7])
        assert all(0.0 < v < 0.003 ** 2 for v in fit.tilt_variance)
