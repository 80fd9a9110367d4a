"""Motion consistency of a verified loop: does the floor motion it measures agree with the odometry?

A loop verified by appearance alone can join two places that merely look alike (a printed, periodic floor; a
repeated tile). Given odometry between the two keyframes (wheel, or visual), the loop's own floor motion (a rigid
fit of its inlier pixel pairs on the floor plane) must lie within the odometry's uncertainty: a Mahalanobis gate
on (dx, dy, dtheta) with the odometry's relative covariance plus the loop measurement's. This is what the SLAM
back end does with its robust kernel; standalone detection (`vslam loops`) applies it per candidate through the
gate hook of `loops.loop_detector.LoopDetector`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from loops.recognition import Verification
from odometry.rigid import ransac_rigid_2d
from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, setting
from odometry.shared.poses import between, wrap_angle

# relative(candidate key, query key) -> (between(pose_candidate, pose_query), its 3x3 covariance)
RelativeMotion = Callable[[int, int], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class MotionGateParams(Config):
    """The motion gate of standalone loop detection (options of `vslam loops`)."""

    chi2: float = setting(16.27, range="(0, inf)",
                          doc="Mahalanobis bound on (dx, dy, dtheta): 16.27 = chi-square 3 dof at 99.9 %")
    pixel_sigma: float = setting(2.0, range="(0, inf)", unit="px",
                                 doc="pixel noise of the loop's inlier keypoints (coarsely coded compact features)")
    threshold_px: float = setting(4.0, range="(0, inf)", unit="px", doc="floor-plane RANSAC inlier distance")
    min_inliers: int = setting(6, range="[2, inf)", doc="fewer pairs on one floor motion: not consistent")
    drift_fraction: float = setting(0.05, range="(0, inf)",
                                    doc="odometry without covariance: 1-sigma position drift per metre travelled "
                                        "(5 %: a poor wheel odometry or visual odometry on a weak texture)")
    drift_rad_per_m: float = setting(0.05, range="(0, inf)", unit="rad/m",
                                     doc="odometry without covariance: 1-sigma heading drift per metre travelled")
    floor_sigma_m: float = setting(0.01, range="(0, inf)", unit="m",
                                   doc="odometry without covariance: position sigma however short the way")


@dataclass(frozen=True)
class GateResult:
    consistent: bool
    mahalanobis2: float        # inf when the loop gave no floor motion
    loop_delta: np.ndarray | None


class PathDriftMotion:
    """Relative motion and a drift-proportional covariance from poses without covariance (e.g. a TUM trajectory
    of `vslam odometry`): sigma grows with the path length travelled between the two keyframes. `unknown` (N,)
    marks frames whose motion from the previous frame was not measured (VO LOST): across one, the relative motion
    is unknown and the covariance is made so large that the gate leaves the decision to appearance."""

    UNKNOWN_SIGMA = 1e6    # m / rad: "no information"

    def __init__(self, poses: np.ndarray, params: MotionGateParams | None = None, unknown: np.ndarray | None = None):
        self.poses = np.asarray(poses, float).reshape(-1, 3)
        self.params = params or MotionGateParams()
        steps = np.linalg.norm(np.diff(self.poses[:, :2], axis=0), axis=1)
        self.arc = np.concatenate([[0.0], np.cumsum(steps)])
        u = np.zeros(len(self.poses), bool) if unknown is None else np.asarray(unknown, bool).reshape(-1)
        self.unknown_before = np.cumsum(u)     # unknown steps up to and including each frame

    def __call__(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        p = self.params
        lo, hi = min(a, b), max(a, b)
        if self.unknown_before[hi] - self.unknown_before[lo] > 0:
            return between(self.poses[a], self.poses[b]), np.eye(3) * self.UNKNOWN_SIGMA ** 2
        length = abs(float(self.arc[b] - self.arc[a]))
        s_xy = p.floor_sigma_m + p.drift_fraction * length
        s_th = p.drift_rad_per_m * max(length, p.floor_sigma_m)
        return between(self.poses[a], self.poses[b]), np.diag([s_xy ** 2, s_xy ** 2, s_th ** 2])


class MotionGate:
    """`gate(candidate_key, query_key, verification)` for `loops.loop_detector.LoopDetector`."""

    def __init__(self, camera: CameraModel, relative: RelativeMotion, params: MotionGateParams | None = None,
                 seed: int = 0):
        self.camera = camera
        self.relative = relative
        self.params = params or MotionGateParams()
        self.rng = np.random.default_rng(seed)
        self.last: GateResult | None = None

    def check(self, candidate: int, query: int, v: Verification) -> GateResult:
        p = self.params
        qpx = np.asarray(v.inliers_query, float).reshape(-1, 2) if np.size(v.inliers_query) else np.zeros((0, 2))
        cpx = np.asarray(v.inliers_candidate, float).reshape(-1, 2) if np.size(v.inliers_candidate) else qpx[:0]
        if len(qpx) < p.min_inliers or len(qpx) != len(cpx):
            return GateResult(False, float("inf"), None)
        res = self.camera.ground_resolution()
        # floor points in the query robot frame map onto the same points in the candidate's: between(cand, query)
        fit = ransac_rigid_2d(self.camera.pixel_to_floor(qpx), self.camera.pixel_to_floor(cpx), p.threshold_px * res,
                              rng=self.rng, sigma_floor=p.pixel_sigma * res)
        if fit is None or fit.n_inliers < p.min_inliers:
            return GateResult(False, float("inf"), None)
        odo, odo_cov = self.relative(candidate, query)
        r = np.asarray(fit.delta, float) - odo
        r[2] = wrap_angle(r[2])
        s = np.asarray(odo_cov, float) + np.asarray(fit.covariance, float) + np.diag([1e-12, 1e-12, 1e-12])
        d2 = float(r @ np.linalg.solve(s, r))
        return GateResult(d2 <= p.chi2, d2, np.asarray(fit.delta, float))

    def __call__(self, candidate: int, query: int, v: Verification) -> bool:
        self.last = self.check(candidate, query, v)
        return self.last.consistent
