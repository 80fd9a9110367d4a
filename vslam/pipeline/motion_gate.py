"""Motion consistency of a verified loop: does the floor motion it measures agree with the odometry?

A loop verified by appearance alone can join two places that merely look alike (a printed, periodic floor; a
repeated tile). Given odometry between the two keyframes (wheel, or visual), the loop's own floor motion (a rigid
fit of its inlier pixel pairs on the floor plane, `loop_pose`) must lie within the odometry's uncertainty: a
Mahalanobis gate on (dx, dy, dtheta) with the odometry's relative covariance plus the loop measurement's.

The odometry's uncertainty is drift-aware (`DriftModel`): odometry errors are mostly biases (a heading scale error
of a few per cent of every turn, a height error that scales every step), so they add up linearly along the path
travelled since the candidate, and a heading error made at one step moves every later position by its lever arm.
The per-step covariance the odometry reports (random noise only) is propagated on top. True loops under 1-3 %
heading drift stay inside the gate; a look-alike place metres away from where the odometry says does not.

The one home of the gate: the SLAM pipeline's loop acceptance and standalone `vslam loops` both use it, through the
gate hook of `loops.loop_detector.LoopDetector`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from loops.recognition import Verification
from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, setting
from odometry.shared.poses import between, compose, inverse, rot2, wrap_angle
from vslam.pipeline.loop_pose import LoopPose, loop_pose

# relative(candidate key, query key) -> (between(pose_candidate, pose_query), its 3x3 covariance)
RelativeMotion = Callable[[int, int], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class DriftModel(Config):
    """1-sigma odometry drift along a path, as biases that add up linearly with distance and turning.

    Defaults: a 2 % scale error (camera height known to 2 %; four times the worst VO drift per metre measured on
    floors, 0.5 %) and a gyro-like heading scale error of 2 % of every turn (a 1-3 % heading drift stays within
    1.5 sigma) plus 0.001 rad per camera height travelled on straight lines (0.11 deg per metre at 0.5 m: ten times
    the heading drift of our VO over 110 m of the independent renderer's printed floor). Visual odometry errs per
    frame, i.e. per image footprint, so its heading drift scales with the camera height, not with metres."""

    trans_fraction: float = setting(0.02, range="[0, inf)", unit="m/m",
                                    doc="position error per metre of displacement between the two poses (scale "
                                        "error)")
    turn_fraction: float = setting(0.01, range="[0, inf)", unit="rad/rad",
                                   doc="heading error per radian turned (heading scale error)")
    heading_rad_per_height: float = setting(0.001, range="[0, inf)", unit="rad per camera height travelled",
                                            doc="heading drift on straight lines (without a camera height: per "
                                                "metre)")
    floor_sigma_m: float = setting(0.01, range="(0, inf)", unit="m",
                                   doc="position sigma however short the way (keeps the gate finite at rest)")

    def scaled(self, factor: float) -> "DriftModel":
        """The same model with its three drift rates times `factor` (the floor sigma unchanged)."""
        return self.replace(trans_fraction=factor * self.trans_fraction, turn_fraction=factor * self.turn_fraction,
                            heading_rad_per_height=factor * self.heading_rad_per_height)


# The pipeline's own VO, as measured: the generic model above scaled by 0.2. On the tuning half (`vslam bench
# loops` seed 1: both renderers' printed and natural floors, the 0.2 Hz lanes; the tuning regimes of `vslam bench
# odometry --regimes`: render_floor at 1/22 and 1/38 of 30 fps, our lanes at 40 m and at 100 m, 0.1 Hz, 60 % shift)
# the smallest factor of the generic model with which every true relative pose between frames more than two camera
# heights of path apart lies inside the gate (chi-square 3 dof, 99.9 %) was 0.013-0.152 (worst: the 100 m lanes),
# rounded up to 0.2 (`python -m vslam.pipeline.drift_calibration SEQ...`). The generic model is 7-75x wider than
# this VO on those floors. Not the pipeline's default: on imagery unlike the simulators' (real aerial scenes with
# relief, a different lens) our VO drifts more, and a gate that narrow would refuse true loops (docs/loops.md).
VO_DRIFT_FACTOR = 0.2


def vo_drift(factor: float = VO_DRIFT_FACTOR) -> "DriftModel":
    """Our VO's drift on simulated and rendered floors: the generic model scaled by `factor` (an option, e.g.
    `--set loops.gate.drift.trans_fraction=0.004 ...`; see docs/loops.md)."""
    return DriftModel().scaled(factor)


@dataclass(frozen=True)
class MotionGateParams(Config):
    """The motion gate of verified loop candidates (pipeline: config section `loops.gate`; `vslam loops`)."""

    enabled: bool = setting(True, doc="check loops against the odometry (False: appearance alone decides)")
    chi2: float = setting(16.27, range="(0, inf)",
                          doc="Mahalanobis bound on (dx, dy, dtheta): 16.27 = chi-square 3 dof at 99.9 %")
    ambiguity_margin: float = setting(6.63, range="[0, inf)",
                                      doc="a query whose gated candidates disagree with each other (two places that "
                                          "cannot both be right: a periodic floor) keeps only the group agreeing "
                                          "with the best, when every other candidate's Mahalanobis distance "
                                          "squared is this much larger (6.63 = chi-square 1 dof at 99 %); "
                                          "else none")
    drift: DriftModel = field(default_factory=DriftModel)
    anchor_loops: bool = setting(True, doc="pipeline: once loops are accepted, judge a candidate against the closed "
                                           "map (the path through an accepted loop near both keyframes, when it is "
                                           "more certain than the VO chain), not the VO chain alone")
    anchor_search: int = setting(4, range="[1, inf)", unit="loops",
                                 doc="accepted loops, nearest along the keyframe chain first, tried as anchors")
    anchor_support: int = setting(2, range="[1, inf)", unit="loops",
                                  doc="an accepted loop anchors the gate once this many accepted loops (itself "
                                      "included) agree with each other through short paths (1: at once); a lone "
                                      "alias then cannot steer the gate")
    refuse_ambiguous: bool = setting(True, doc="pipeline: once a query has matched two places that cannot both be "
                                               "right (two candidates with a floor fit, the motion refusing one or "
                                               "not), refuse every candidate whose gate is wide enough to pass a "
                                               "place that far off as well (undecidable from the motion; from that "
                                               "query on)")
    cluster_queries: int = setting(0, range="[0, inf)", unit="query keyframes",
                                   doc="pipeline, on a floor with look-alikes (a verified candidate the motion "
                                       "refused): a loop not anchored by an accepted one needs a candidate of one "
                                       "of this many previous queries agreeing with it (0: off)")
    drift_in_graph: bool = setting(True, doc="pipeline: the pose graph's odometry edges carry the drift model's "
                                             "per-step variance too (the VO's own covariance is random noise only: "
                                             "beside it, true loops look inconsistent and the back end drops them)")


@dataclass(frozen=True)
class GateResult:
    consistent: bool
    mahalanobis2: float           # inf when the loop gave no floor motion
    fit: LoopPose | None          # the loop's floor motion (pose of the query in the candidate's frame)
    # why it was refused ("" when consistent): "no fit" (no rigid floor motion), "motion" (outside the gate),
    # "alias" (the gate would pass the floor's alias too), "cluster" (no agreeing query nearby), "ambiguous" (the
    # query's gated candidates disagree), so that a run can say at which stage its true loops were lost
    refused: str = ""


def step_drift_covariance(step: np.ndarray, drift: DriftModel, height: float = 1.0) -> np.ndarray:
    """The drift model's variance of one odometry step (x, y, theta), as independent noise: a pose-graph edge."""
    d = float(np.hypot(step[0], step[1]))
    s_th = drift.turn_fraction * abs(float(wrap_angle(float(step[2])))) + drift.heading_rad_per_height * d / height
    s_xy = drift.trans_fraction * d
    return np.diag([s_xy ** 2, s_xy ** 2, s_th ** 2])


UNKNOWN_SIGMA = 1e6    # m / rad: "no information" across a step whose motion was not measured


class ChainMotion:
    """Relative motion between two poses of a chain (per frame or per keyframe) and its drift-aware covariance.

    `poses` (N, 3) in increasing key order, `keys` (N,) their frame ids (default 0..N-1), `height` the camera
    height (m; the unit of distance of `DriftModel.heading_rad_per_height`). `step_cov` (N, 3, 3):
    covariance of the step from pose i-1 to pose i in the frame of pose i-1 (the odometry's own, random part;
    None: none). `unknown` (N,): the step into pose i was not measured (VO lost); across one, the relative motion
    is unknown and the gate leaves the decision to appearance."""

    def __init__(self, poses: np.ndarray, drift: DriftModel | None = None, keys: np.ndarray | None = None,
                 step_cov: np.ndarray | None = None, unknown: np.ndarray | None = None, height: float = 1.0):
        self.poses = np.asarray(poses, float).reshape(-1, 3)
        self.height = float(height)
        self.drift = drift or DriftModel()
        n = len(self.poses)
        self.keys = np.arange(n) if keys is None else np.asarray(keys, int).reshape(-1)
        self.step_cov = None if step_cov is None else np.asarray(step_cov, float).reshape(n, 3, 3)
        u = np.zeros(n, bool) if unknown is None else np.asarray(unknown, bool).reshape(-1)
        self.unknown_before = np.cumsum(u)     # unknown steps up to and including each pose

    def _index(self, key: int) -> int:
        i = int(np.searchsorted(self.keys, key))
        if i >= len(self.keys) or self.keys[i] != key:
            raise KeyError(f"no pose for key {key}")
        return i

    def __call__(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """between(pose a, pose b) and its covariance (keys a <= b: the candidate is the older one)."""
        ia, ib = self._index(a), self._index(b)
        if ia > ib:
            raise ValueError(f"relative motion from key {a} to the earlier key {b}")
        rel = between(self.poses[ia], self.poses[ib])
        d = self.drift
        if self.unknown_before[ib] - self.unknown_before[ia] > 0:
            return rel, np.eye(3) * UNKNOWN_SIGMA ** 2
        if ib == ia:
            return rel, np.diag([d.floor_sigma_m ** 2] * 2 + [1e-12])
        seg = self.poses[ia:ib + 1]
        c, s = np.cos(seg[0, 2]), np.sin(seg[0, 2])
        xy = (seg[:, :2] - seg[0, :2]) @ np.array([[c, -s], [s, c]])   # positions in pose a's frame
        th = seg[:, 2] - seg[0, 2]
        step = np.linalg.norm(np.diff(xy, axis=0), axis=1)             # (m,) step lengths
        turn = np.abs(wrap_angle(np.diff(th)))                          # (m,) turns
        lever = xy[-1] - xy[1:]                                         # (m, 2) step end -> last position
        s_heading = d.turn_fraction * turn + d.heading_rad_per_height * step / self.height   # per step
        # biases: errors of one sign along the way, so sigmas add (not variances)
        # a scale error moves the end by a fraction of the displacement (it cancels around a closed loop); a heading
        # error made at step k moves every later position by its lever arm to the end
        s_xy = d.floor_sigma_m + d.trans_fraction * float(np.linalg.norm(xy[-1])) \
            + float(s_heading @ np.linalg.norm(lever, axis=1))
        s_th = float(s_heading.sum())
        cov = np.diag([s_xy ** 2, s_xy ** 2, s_th ** 2])
        if self.step_cov is not None:
            # random part: J_k C_k J_k^T, J_k = [[R(theta_{k-1}), perp(lever_k)], [0, 0, 1]]
            jac = np.zeros((len(step), 3, 3))
            jac[:, :2, :2] = rot2(th[:-1])               # step k's frame -> pose a's frame
            jac[:, 0, 2], jac[:, 1, 2], jac[:, 2, 2] = -lever[:, 1], lever[:, 0], 1.0
            cov = cov + np.einsum("kij,kjl,kml->im", jac, self.step_cov[ia + 1:ib + 1], jac)
        return rel, 0.5 * (cov + cov.T)


class MotionGate:
    """`gate(candidate_key, query_key, verification)` for `loops.loop_detector.LoopDetector`.

    `fit(verification)` gives the loop's floor motion (None: too few pairs on one rigid motion, so the loop cannot
    be checked and is not consistent); `relative` the odometry between two keys. Every verdict is kept in
    `results[(candidate, query)]`, so the pipeline gives the graph the same fit the gate judged."""

    def __init__(self, fit: Callable[[Verification], LoopPose | None], relative: RelativeMotion,
                 params: MotionGateParams | None = None, image_sigma_rms: float = 0.0):
        self.fit = fit
        self.relative = relative
        self.params = params or MotionGateParams()
        self.image_sigma_rms = float(image_sigma_rms)
        self.results: dict[tuple[int, int], GateResult] = {}

    def fit_covariance(self, fit: LoopPose) -> np.ndarray:
        """The loop's covariance as judged: its fit's, plus each image's registration error (`image_sigma_rms`
        fit RMS residuals per axis and image, common to all its pairs; the pipeline's graph adds the same)."""
        s2 = 2.0 * (self.image_sigma_rms * fit.rms) ** 2
        return np.asarray(fit.covariance, float) + np.diag([s2, s2, 0.0])

    @classmethod
    def for_camera(cls, camera: CameraModel, relative: RelativeMotion, params: MotionGateParams | None = None,
                   threshold_px: float = 4.0, min_inliers: int = 6, pixel_sigma: float = 2.0,
                   seed: int = 0) -> "MotionGate":
        """The gate with the floor fit of `loop_pose` (threshold_px: RANSAC inlier distance, pixel_sigma: noise of
        the coarsely coded keypoints, both in pixels)."""
        rng = np.random.default_rng(seed)

        def fit(v: Verification) -> LoopPose | None:
            q = np.asarray(v.inliers_query, float).reshape(-1, 2) if np.size(v.inliers_query) else np.zeros((0, 2))
            c = np.asarray(v.inliers_candidate, float).reshape(-1, 2) if np.size(v.inliers_candidate) else q[:0]
            if len(q) != len(c):
                return None
            return loop_pose(camera, q, c, threshold_px, min_inliers, pixel_sigma, rng)
        return cls(fit, relative, params)

    def check(self, candidate: int, query: int, v: Verification) -> GateResult:
        fit = self.fit(v)
        if fit is None:
            return GateResult(False, float("inf"), None, "no fit")
        odo, odo_cov = self.relative(candidate, query)
        r = np.asarray(fit.delta, float) - odo
        r[2] = wrap_angle(r[2])
        s = np.asarray(odo_cov, float) + self.fit_covariance(fit) + np.eye(3) * 1e-12
        d2 = float(r @ np.linalg.solve(s, r))
        return GateResult(d2 <= self.params.chi2, d2, fit, "" if d2 <= self.params.chi2 else "motion")

    def __call__(self, candidate: int, query: int, v: Verification) -> bool:
        res = self.check(candidate, query, v)
        self.results[(int(candidate), int(query))] = res
        return res.consistent

    def agree(self, a: int, b: int, query: int) -> bool:
        """Do the loops (a, query) and (b, query) put the query at one place? Their fits imply the motion from
        candidate a to candidate b, which the odometry between the two candidates also measures."""
        if a > b:
            a, b = b, a
        fa, fb = self.results[(a, query)].fit, self.results[(b, query)].fit
        odo, cov = self.relative(a, b)
        r = compose(fa.delta, inverse(fb.delta)) - odo
        r[2] = wrap_angle(r[2])
        s = cov + self.fit_covariance(fa) + self.fit_covariance(fb) + np.eye(3) * 1e-12   # first order; independent
        return float(r @ np.linalg.solve(s, r)) <= self.params.chi2

    def resolve(self, query: int, candidates: list[int]) -> list[int]:
        """Of the candidates of `query` that passed the gate, those to keep: all when they agree with each other;
        else the group agreeing with the most consistent one if every other is worse by `ambiguity_margin`
        (Mahalanobis distance squared), else none (an ambiguous place)."""
        if len(candidates) < 2:
            return list(candidates)
        ranked = sorted(candidates, key=lambda c: self.results[(c, query)].mahalanobis2)
        best = ranked[0]
        group = [best] + [c for c in ranked[1:] if self.agree(best, c, query)]
        others = [c for c in ranked if c not in group]
        if not others:
            return group
        gap = self.results[(others[0], query)].mahalanobis2 - self.results[(best, query)].mahalanobis2
        kept = group if gap >= self.params.ambiguity_margin else []
        for c in candidates:
            if c not in kept:
                r = self.results[(c, query)]
                self.results[(c, query)] = GateResult(False, r.mahalanobis2, r.fit, "ambiguous")
        return kept
