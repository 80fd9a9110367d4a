"""The relative pose of a loop on the floor: the verified keypoint pairs back-projected with the camera model,
then a robust rigid fit (the same Kabsch + RANSAC as the visual odometry)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odometry.rigid import ransac_rigid_2d
from odometry.shared.camera import CameraModel


@dataclass(frozen=True)
class LoopPose:
    delta: np.ndarray        # (3,) pose of the query keyframe in the frame of the matched keyframe
    covariance: np.ndarray   # (3, 3)
    n_inliers: int
    rms: float               # metres


def loop_pose(camera: CameraModel, query_px: np.ndarray, match_px: np.ndarray, threshold_px: float,
              min_inliers: int, pixel_sigma: float, rng: np.random.Generator) -> LoopPose | None:
    """None when fewer than `min_inliers` pairs agree on one rigid motion of the floor."""
    if len(query_px) < max(min_inliers, 2):
        return None
    res = camera.ground_resolution()
    src = camera.pixel_to_floor(query_px)      # floor points in the query robot frame
    dst = camera.pixel_to_floor(match_px)      # the same points in the matched robot frame
    fit = ransac_rigid_2d(src, dst, threshold_px * res, rng=rng, sigma_floor=pixel_sigma * res)
    if fit is None or fit.n_inliers < min_inliers:
        return None
    return LoopPose(delta=fit.delta, covariance=fit.covariance, n_inliers=fit.n_inliers, rms=fit.rms)
