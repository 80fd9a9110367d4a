"""Downward-camera visual odometry: keyframe LK tracking -> floor points -> Kabsch inside RANSAC (seed 001 §IV-D).

Per frame:

1. predict the motion since the previous frame (the fused wheel/gyro motion when given, else constant velocity);
2. predict where the keyframe's corners are now (through the floor plane) and refine them with pyramidal LK
   started there (sub-pixel; the template is always the keyframe, so there is no drift between keyframes);
3. back-project the tracked pixels onto the floor with `CameraModel.pixel_to_floor` (distortion, height, tilt,
   mount) and fit the planar rigid motion keyframe -> current frame by 2-point RANSAC + centroid-removed SVD
   refined on all inliers; its covariance comes from the inlier residuals and the point spread (J^T J);
4. if that fails, match the previous frame instead; if that fails too, the frame is a failure: the motion is the
   fallback (fused wheel/gyro) with an inflated covariance (status FALLBACK) or, without one, a constant-velocity
   guess with a large covariance (status LOST). Never a silent zero motion;
5. start a new keyframe when too few keyframe corners remain trackable, the rotation is large, or tracking failed
   on a usable frame.

Direction convention: floor points of the current frame (its base frame) are mapped onto the keyframe's floor
points; that rigid transform is the pose of the current frame in the keyframe's frame (`odometry.shared.poses.compose`).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Callable

import cv2
import numpy as np

from odometry.descriptor_path import Features, match_features, orb_features
from odometry.errors import OdometryError
from odometry.height import Height, HeightTracker, WobbleEstimate
from odometry.height_link import HeightLinks
from odometry.lattice import view_lattice
from odometry.rigid import RigidFit, kabsch_2d, ransac_rigid_2d
from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, ConfigError, setting
from odometry.shared.pose_covariance import between_with_covariance, compose_with_covariance
from odometry.shared.poses import between, compose, wrap_angle
from odometry.tilt_refine import refine_planar_tilt
from odometry.tracking import (
    BadImage,
    aperture_weights,
    coarse_shift,
    contrast,
    detect_corners,
    highpass,
    normalize,
    normalize_local,
    structure_tensors,
    to_gray,
    track_lk,
)

__all__ = ["Method", "Photometric", "Reference", "VOConfig", "VOEstimate", "VOStatus", "VOTrajectory", "VisualOdometry",
           "run_visual_odometry"]


class VOStatus(str, Enum):
    """Where a frame's motion comes from."""

    INIT = "init"          # the first frame: the origin
    OK = "ok"              # measured by vision
    FALLBACK = "fallback"  # vision failed: the given fallback motion (fused wheel/gyro), covariance inflated
    LOST = "lost"          # vision failed and no fallback: constant-velocity guess with a large covariance


class Photometric(str, Enum):
    """How frames are normalised before LK (brightness constancy against lighting changes and vignetting)."""

    NONE = "none"
    GLOBAL = "global"       # gain and offset of the whole frame
    HIGHPASS = "highpass"   # minus the local box mean: removes smooth light fields (default; 0.3 ms)
    LOCAL = "local"         # local mean and contrast: the most invariant, ~10x the cost of HIGHPASS


class Reference(str, Enum):
    """What the current frame was matched against."""

    NONE = "none"
    KEYFRAME = "keyframe"
    PREVIOUS = "previous"
    REACQUIRED = "reacquired"  # an earlier keyframe, after tracking was lost (the trajectory is re-attached)


class Method(str, Enum):
    """How the correspondences of a frame were found (odometry.csv column `method`)."""

    NONE = "none"              # vision did not measure this frame
    LK = "lk"                  # the fast path: LK from the motion prediction (derotated when it predicts a turn)
    LK_PYRAMID = "lk-pyramid"  # LK with a deep pyramid (a poor or missing prediction)
    LK_SHIFT = "lk-shift"      # LK from a phase-correlation shift
    ORB_LK = "orb+lk"          # ORB matches gave the motion, LK on the keyframe corners refined it
    ORB = "orb"                # ORB matches alone (LK could not refine them)


@dataclass(frozen=True)
class VOConfig(Config):
    """Every tunable of the visual odometry (presets: `default`, `fast`; `VOConfig.preset(name)`).

    Front end: corners (Shi-Tomasi) are detected at keyframes only, spread over `grid`; LK tracks them in every
    frame from the motion prediction. Robust fit: thresholds are in pixels and converted to metres with the
    camera's ground resolution. Keyframes: a new one starts when fewer than `keyframe_min_inliers` or
    `keyframe_min_fraction` of its corners remain inliers, or the rotation since it exceeds
    `keyframe_max_rotation` (LK windows do not rotate).

    Covariance: sigma^2 (J^T J)^-1 of the fit (residual-based, sigma never below `pixel_sigma`, times
    `covariance_scale`). With `refine_tilt` the robot's pitch, roll (prior `tilt_sigma`, rad) and bounce (prior
    `height_sigma`, m) are estimated with the motion and marginalised into it. Without it, their effect is added
    as a model term: a tilt shifts the whole view like a translation of camera_height * tilt, slowly
    (correlation time `wobble_time`, s), so between frames dt apart a fraction 2 (1 - exp(-dt / wobble_time)) of
    that variance appears; `tilt_rotation_coupling` is the heading error per radian of tilt. Fallback
    covariances are multiplied by `fallback_inflation`.
    """

    LABEL = "VO"
    PRESETS = {
        "default": {},
        # fewer corners and a plain rigid fit (no tilt refinement). Measured on the natural floors: about 1.8x the
        # frame rate of `default`, drift 0.16 % instead of 0.11 %
        "fast": {"max_features": 120, "refine_tilt": False, "keyframe_min_inliers": 40, "ransac_iterations": 100},
    }

    max_features: int = setting(200, range="[1, inf)", doc="corners detected at a keyframe")
    grid: tuple[int, int] = setting((8, 6), range="[1, inf)", doc="cells (columns, rows) the corners are spread over")
    quality: float = setting(0.01, range="(0, 1]", doc="Shi-Tomasi quality level, relative to the best corner")
    min_distance: float = setting(14.0, range="[0, inf)", unit="px", doc="between detected corners")
    half_resolution_detection: bool = True
    border: int = setting(16, range="[0, inf)", unit="px")
    lk_window: int = setting(15, range="[5, inf)", unit="px", doc="LK window side, odd")
    lk_levels: int = setting(0, range="[0, inf)", doc="LK pyramid levels above the full image")
    lk_iterations: int = setting(20, range="[1, inf)")
    lk_epsilon: float = setting(0.02, range="[0, inf)", unit="px")
    lk_min_eig: float = setting(1e-3, range="[0, inf)")
    photometric: Photometric = Photometric.HIGHPASS
    photometric_radius: int = setting(8, range="[0, inf)", unit="px")
    min_contrast: float = setting(2.0, range="[0, inf)", unit="grey levels")
    min_features: int = setting(25, range="[0, inf)", doc="fewer corners at a keyframe: vision fails")
    ransac_threshold_px: float = setting(1.5, range="(0, inf)", unit="px")
    ransac_iterations: int = setting(200, range="[1, inf)")
    ransac_confidence: float = setting(0.999, range="(0, 1]")
    min_inliers: int = setting(20, range="[3, inf)")
    min_inlier_ratio: float = setting(0.35, range="[0, 1]")
    keyframe_min_inliers: int = setting(60, range="[0, inf)")
    keyframe_min_fraction: float = setting(0.4, range="[0, 1]")
    keyframe_max_rotation: float = setting(math.radians(12.0), range="[0, inf)", unit="rad")
    pixel_sigma: float = setting(0.05, range="[0, inf)", unit="px")
    covariance_scale: float = setting(1.0, range="[0, inf)")
    refine_tilt: bool = True
    tilt_sigma: float = setting(0.003, range="[0, inf)", unit="rad")
    height_sigma: float = setting(0.002, range="[0, inf)", unit="m")
    wobble_time: float = setting(2.0, range="(0, inf)", unit="s")
    tilt_rotation_coupling: float = setting(0.15, range="[0, inf)", unit="rad/rad")
    fallback_inflation: float = setting(4.0, range="[0, inf)")
    lost_sigma_xy: float = setting(0.05, range="[0, inf)", unit="m")
    lost_sigma_theta: float = setting(0.1, range="[0, inf)", unit="rad")
    max_failures_before_reset: int = setting(2, range="[0, inf)")
    coarse_retry: bool = True
    retry_levels: int = setting(3, range="[0, inf)")
    coarse_min_response: float = setting(0.05, range="[0, inf)")
    # a periodic floor (a printed photograph tiled every 0.256 m on render_floor) has a copy of the view one period
    # away: the deep pyramid's coarse levels can settle on that copy (255 px off the start, beyond the ~112 px
    # that 3 levels of a 15 px window can reach), and a phase correlation peak can sit on it too. The pyramid retry
    # keeps only a motion within its capture range of its start (`VisualOdometry._capture_range`), and with wheel
    # odometry the phase-correlation start must pass `prediction_gate` like a descriptor motion
    retry_capture_check: bool = setting(True, doc="the deep-pyramid LK retry keeps only a motion within its capture "
                                                  "range (half the LK window x (2^(levels+1) - 1) px) of its start")
    shift_gate: bool = setting(True, doc="with wheel odometry, a motion found from the phase-correlation start must "
                                         "pass prediction_gate")
    # the prediction gate is as wide as the wheel odometry is uncertain (render_floor's fused motion: 25 mm per
    # 15 mm frame, x2 inflated, 6 sigma: 300 mm, more than a 256 mm period). At high frame rates the motion vision
    # measured on the previous frame bounds the robot far tighter (prediction_accel: 4 px at 20 frames/s), so a
    # descriptor or phase-correlation motion outside that bound is a copy of the view or a wrong place; and a weak
    # LK fit from the wheel prediction outside it is first retried from that motion (the deep-pyramid retry, which
    # starts from the wheel prediction, is bounded by its capture range instead)
    cv_gate: bool = setting(True, doc="with wheel odometry, when the constant-velocity motion is known within LK's "
                                      "capture range, a descriptor or phase-correlation motion must agree with it "
                                      "(within its bound + orb_threshold_px)")
    # LK windows (15 px) are not rotated, so the current frame is first rotated back by the rotation since the
    # keyframe (about the principal point: exact for a radial lens). Not only beyond LK's linear range (~20
    # degrees): a window rotated by phi is a misfit of its translation-only model (its corners move by phi x
    # 10.6 px), which biases where LK settles on edge-like texture. 0.05 rad (3 degrees, 0.5 px at the window's
    # corners, ~5x LK's precision) derotates the frames of a turn at any frame rate (the keyframe rule renews at 12
    # degrees): on the independent renderer's floors in turns, point errors stayed at 0.1 px instead of growing to
    # 0.36 px by 9-12 degrees, and the 1 m drift fell ~40 % (docs/odometry.md, item 13). 0.35 was the previous
    # default (derotate only beyond the linear range; never at high frame rates).
    lk_max_rotation: float = setting(0.05, range="[0, inf)", unit="rad",
                                     doc="rotation since the keyframe (predicted, measured on the predicted pixels) "
                                         "above which LK runs on the current frame rotated back")
    descriptors: bool = setting(True, doc="ORB matching when LK fails, to initialise and to re-acquire")
    orb_features: int = setting(1500, range="[10, inf)", doc="ORB keypoints per frame on the descriptor path")
    orb_fast_threshold: int = setting(8, range="[1, 255]", unit="grey levels", doc="FAST threshold of ORB")
    orb_ratio: float = setting(0.8, range="(0, 1]", doc="Lowe's ratio test on Hamming distances")
    orb_threshold_px: float = setting(3.0, range="(0, inf)", unit="px",
                                      doc="RANSAC inlier distance for ORB matches (ORB keypoints are ~0.6 px RMS)")
    orb_min_inliers: int = setting(12, range="[3, inf)", doc="fewer ORB inliers: the descriptor path fails")
    orb_min_inlier_ratio: float = setting(0.1, range="[0, 1]",
                                          doc="of the ratio-test survivors (many lie outside the overlap)")
    # a weakly textured floor (bare concrete) gives FAST few corners above orb_fast_threshold in the overlap: on a
    # render_floor concrete pair turned by 34 degrees and shifted by 40 % of the footprint, 1500 ORB at 8 grey
    # levels held 8 correct matches, 5000 at 3 grey levels 100. The denser set costs ~4x to detect and ~10x to
    # match, so it is only a retry when the first set gave no motion (never on the LK fast path)
    orb_dense_features: int = setting(5000, range="[0, inf)",
                                      doc="ORB keypoints of the retry on a descriptor failure (0: no retry)")
    orb_dense_fast_threshold: int = setting(3, range="[1, 255]", unit="grey levels",
                                            doc="FAST threshold of the dense retry")
    # at high frame rates LK tracks most of the 200 keyframe corners (about 150-200 inliers), so the check costs
    # nothing there; at a low rate a correct LK start tracks 20-60 of them, as does a wrong one on grass
    lk_weak_inliers: int = setting(60, range="[0, inf)",
                                   doc="an LK fit with fewer inliers is checked against the descriptor path")
    # ... unless the fit explains most of the keyframe corners it puts in view: at high rates the inliers fall to
    # 60 only as corners leave the image, just before the keyframe is renewed (a fit tracking 90 % of what it can
    # see is not a wrong settle), and running ORB there cost 57 ms on 5 % of a 100 m carpet run's frames
    lk_weak_visible_fraction: float = setting(0.5, range="[0, 1]", unit="fraction of the keyframe corners in view",
                                              doc="a weak LK fit is checked only if its inliers are fewer than this "
                                                  "fraction of the keyframe corners it puts inside the image")
    orb_hypotheses: int = setting(3, range="[1, inf)", doc="RANSAC consensus sets tried in turn until LK confirms one")
    # render_floor's mosaic holds rotated copies of the same photographs: 67 ORB inliers at a wrong place were
    # seen, so an unconfirmed ORB motion must be far stronger than that
    orb_strong_inliers: int = setting(150, range="[3, inf)",
                                      doc="an ORB fit with this many inliers (and orb_strong_ratio) needs no LK")
    orb_strong_ratio: float = setting(0.5, range="[0, 1]")
    # LK confirms a place when it tracks a good share of the corners that place puts in view: a repeated copy of a
    # texture patch covers only part of the view. Re-acquisition (any of several keyframes) asks for more.
    orb_confirm_fraction: float = setting(0.3, range="[0, 1]",
                                          doc="LK inliers / keyframe corners in view to confirm an ORB motion")
    reacquire_min_fraction: float = setting(0.5, range="[0, 1]", doc="the same when re-acquiring")
    # among the confirmed hypotheses, the one with the most LK inliers wins: the share of the corners in view
    # rewards a place that puts few corners in view (render_floor grass s3 at 0.2 Hz: a rotated copy of a texture
    # patch, 30 of 45 corners, against the true place's 51 of 79; the LK fits' own RANSAC decided the tie by seed)
    orb_hypothesis_evidence: str = setting("inliers", choices=("inliers", "share"),
                                           doc="how confirmed ORB hypotheses are compared: LK inlier count, or "
                                               "LK inliers / keyframe corners in view (the rule before 2026-11-29)")
    prediction_gate: float = setting(6.0, range="(0, inf)", unit="sigma",
                                     doc="a descriptor motion this far from the given fallback motion is rejected")
    # a periodic floor (one printed photograph tiled) shows the same view at every lattice step p of its period:
    # vision cannot tell the motions t + k p apart, and the ORB consensus of the largest overlap (the smallest image
    # motion) wins although the true place is another copy. With wheel odometry at a low frame rate the prediction
    # gate (6 sigma of the inflated wheel covariance: 480 mm for 40 mm stated) holds several copies of a 256 mm
    # period. The keyframe's ORB features matched against themselves measure its lattice; the copies of a
    # descriptor or phase-correlation motion inside the gate that LK confirms as well are weighed by the
    # prediction alone (their image evidence is the same), and the frame is refused when none is clearly likeliest
    alias_guard: bool = setting(True, doc="with wheel odometry, a descriptor or phase-correlation motion on a "
                                          "self-similar keyframe is chosen among its confirmed copies one lattice "
                                          "step apart by the prediction, or refused")
    # a wrong copy costs a whole period (256 mm on the printed floor), a refused frame only the wheel odometry's own
    # error for that frame (20-40 mm): a copy is kept when the chance that it is the wrong one is below ~10 %
    alias_confidence: float = setting(0.9, range="[0, 1]", unit="probability",
                                      doc="posterior of the chosen copy among the confirmed copies (Gaussian "
                                          "likelihood under the prediction's covariance); below it the frame is "
                                          "refused")
    # an exact copy is tracked by LK as well as the place itself (share ~1 each on the printed floor); a place that
    # only resembles it (a real tiled floor) tracks far fewer of the corners it puts in view
    alias_support: float = setting(0.5, range="[0, 1]", unit="ratio of LK shares",
                                   doc="a copy counts when LK tracks at least this share of the first motion's "
                                       "tracked share of the corners in view")
    reacquire_keyframes: int = setting(6, range="[0, inf)",
                                       doc="recent keyframes a frame is matched against after tracking was lost")
    reanchor_frames: int = setting(100, range="[0, inf)",
                                   doc="frames after a loss during which each frame tries to re-attach to them")
    # the camera height is not constant (suspension, floor unevenness; a drone's altitude hold): a height error is
    # a scale error of every motion. The tilt refinement measures each frame's height relative to its keyframe;
    # a new keyframe gets the chained height when it departs significantly from the mean over `height_window`
    # (taken to be the nominal camera_height), else the nominal height (odometry.height)
    track_height: bool = setting(True, doc="estimate the camera height frame by frame (needs refine_tilt)")
    # the tilt wobble is slow next to the frame rate (correlation time wobble_time), and with the view's overlap off
    # the image centre a tilt the refinement does not resolve passes into the measured height ratio: zero-mean tilt
    # priors biased every height link by the common tilt of its two frames (our simulator's carpet loop: link error
    # ~ -0.18 x pitch, lag-1 correlation 0.6, so the chain strayed). Carried, each refinement starts from the
    # keyframe's own estimated tilt and from the previous frame's decayed by exp(-dt / wobble_time). Off by default:
    # it halves the links' error there (RMS 0.068 -> 0.037 %, NEES 5.7 -> 1.9) but the VO ATE is mixed (carpet loop
    # seeds 0/1/2: 0.0207/0.0237/0.0249 -> 0.0218/0.0121/0.0310 %): the links' errors stay correlated (docs/odometry.md)
    carry_tilt: bool = setting(False, doc="prior means of the tilt refinement's tilts: the keyframe's estimated "
                                         "tilt and the previous frame's (decayed over wobble_time) instead of 0 "
                                         "(needs track_height)")
    # the bounce of a suspension or of floor unevenness decorrelates within a few seconds, a drone's altitude hold
    # within ~10 s: over this window the height is taken to average to camera_height. The chain's random-walk
    # error grows with it, the bias of a slow height change shrinks with it.
    height_window: float = setting(10.0, range="(0, inf)", unit="s",
                                   doc="time over which the camera height is taken to average to camera_height")
    # the departure is the chained log height minus its window mean; sigma is what the chained measurements'
    # own variances allow within the window. Graded (default): the posterior mean of the departure under a
    # zero-mean prior whose variance is the heights' own spread over the window (nothing to set). The switch
    # (height_graded=false) uses a departure only above height_significance sigma (3: a noise departure is used
    # 0.3 % of the time) and then in full: on render_floor's planks/slats/brick floors it left keyframes with real
    # departures up to ~0.6 % at the nominal height (the height links of edge-like windows in turns are noisier)
    height_significance: float = setting(3.0, range="[0, inf)", unit="sigma",
                                         doc="with height_graded=false: a keyframe's measured height departure "
                                             "below this is not used")
    height_graded: bool = setting(True, doc="use the measured height departure shrunk by inverse variances (the "
                                            "posterior mean) instead of the height_significance switch")
    # the prior variance of the graded estimate is the heights' spread over the window less this share of the
    # chain's accumulated variance V. A pure random walk spreads by V / 6 on average; the links' variances are
    # too small by ~4x on our simulator (its tilt wobble couples to the height), so all of V: measured on the
    # tuning runs, 1/6 -> 1 moved render_floor's rows by <= 0.004 % and our 5 cm camera run 0.025 -> 0.021 % ATE
    height_noise_spread: float = setting(1.0, range="[0, inf)", unit="x chain variance",
                                         doc="share of the chained height variance taken as noise in the graded "
                                             "estimate's prior")
    # the tilt refinement's height variance counts the tilts it leaves to its priors as independent between the
    # two frames of a link; a real wobble is slow (wobble_time) and shared by them and by consecutive links (a
    # keyframe ends one link and starts the next), so its error in the chained height adds up coherently (our
    # simulator's carpet loop: links 0.070 % RMS off against 0.034 % stated, lag-1 correlation 0.58). With this,
    # each link's variance is its image-noise part plus the covariance of its tilt part (the refinement's
    # d s / d tilt) with the whole chain under a wobble of correlation exp(-dt / wobble_time) (odometry.height,
    # Height.moved_coupled): what the graded estimate's sigma_d^2 and S^2 are built on
    height_tilt_coupling: bool = setting(True, doc="height links: count the tilt part of their error as a wobble "
                                                    "shared between frames over wobble_time (correlated links) "
                                                    "instead of independent per frame (needs track_height)")
    # the wobble's standard deviation, estimated from the tilts the refinement measures (odometry.height.
    # WobbleEstimate), starting from this many estimates at tilt_sigma (four per refined frame): 8 lets the data
    # decide within two frames (a camera that does not tilt, render_floor: ~0 then; 120, i.e. ~1 s at 30 fps of
    # tilt_sigma, overstated its early links: wood-slats+brick s38 0.221 -> 0.250 %/m); 0 takes tilt_sigma itself
    wobble_estimate: float = setting(8.0, range="[0, inf)", unit="tilt estimates",
                                     doc="prior weight of tilt_sigma in the online wobble estimate of "
                                         "height_tilt_coupling (0: tilt_sigma is the wobble)")
    # two options of the graded estimate (odometry.height), off by default: on the independent renderer (honest
    # link variances) they lower the 30 fps drift, on our simulator (link variances ~4x too small) they raise it
    # (docs/odometry.md item 10). random_walk_sigma: sigma_d^2 is what the chain's random walk strays from its
    # window mean (V / 3), not all of V
    height_random_walk_sigma: bool = setting(False, doc="graded height: count only the chain's random-walk scatter "
                                                        "about its window mean as the departure's noise")
    # height_start_sigma: before the window is full, the first frame's own uncertainty about camera_height (0.002
    # is 1 mm at 0.5 m, a rule at rest) instead of the spread of the heights seen so far
    height_start_sigma: float | None = setting(None, range="[0, inf)", unit="relative (log height)",
                                               doc="graded height: the first frame's standard deviation about "
                                                   "camera_height (None: the heights' spread so far)")
    # a height chain's link errors pass unseen into every later keyframe: measuring each new keyframe's height
    # against the keyframe before the last one too (when its view still overlaps) closes a triangle whose two paths
    # are fused by inverse variances (odometry.height_link; one more LK pass per keyframe)
    height_redundant: bool = setting(False, doc="also measure each new keyframe's height against keyframe k-2 and "
                                                "fuse it with the chain through k-1 (needs track_height)")
    # before the triangles' own disagreement (their NEES) is trusted for the gate, it is taken to be 1 over this
    # many triangles (a handful of early triangles must not open or shut the gate)
    height_link_prior: float = setting(5.0, range="[0, inf)", unit="triangles",
                                       doc="prior weight of NEES = 1 in the redundant height link's gate")
    # LK on keyframe k-2's corners can settle at a wrong place when little of its view is left: the link is used
    # only when the two paths agree within this many standard deviations (scaled by the measured NEES)
    height_link_gate: float = setting(3.0, range="(0, inf)", unit="sigma",
                                      doc="largest disagreement of the two height paths for link k-2 to be used")
    # the fused variance (independent paths) is smaller than the chain's; an error of the frame's own view is common
    # to both paths and unseen by the triangle, so the chain's variance is kept by default: on our simulator's
    # 100 m carpet loop (tilt coupled into the height) the fused variance made VO ATE 0.021 -> 0.033 % at seed 0
    # (0.017 % keeping the chain's); on render_floor (honest links) it was 0.005 %/m better (docs/odometry.md)
    height_link_shrink_variance: bool = setting(False, doc="give the keyframe the fused variance of the two height "
                                                           "paths instead of the single chain's")
    # LK fixes a window's position only across its edges (the aperture problem): on planks, grain and brick
    # courses many windows are edge-like, and their error along the edge enters the refined motion and height
    # off by default: it lowers render_floor's reporting rows (wood planks + brick most) but raises its two tuning
    # rows by 0.007-0.017 % and makes the batch back end reject 9 of 49 true loops under a 3 % heading drift
    # (tests/vslam/test_backend_drift.py) - see docs/odometry.md, item 11
    aperture_weighting: bool = setting(False, doc="weigh each LK point's residual by the shape of its structure "
                                                  "tensor in the tilt refinement (needs refine_tilt)")
    # the motion vision measured on the previous frame, at constant velocity, is known to within what the robot
    # can accelerate in one frame time: at high frame rates a few pixels, often better than the wheel odometry
    # (on our simulator's 1 m/s carpet loop the fused wheel/gyro motion is off by ~5 mm forward and ~4 mm sideways
    # per frame, 4-5 px, up to 30 px in a slip). It is a second LK start when LK from the prediction fails, and
    # a weak LK fit that agrees with it needs no descriptor check (see VisualOdometry._holds); at low frame rates
    # its uncertainty (growing as dt^2) exceeds LK's capture range and it is not used
    prediction_accel: float = setting(2.0, range="[0, inf)", unit="m/s^2",
                                      doc="acceleration allowed for in the constant-velocity motion (hard braking "
                                          "of a ground robot); 0: no constant-velocity start or check")
    prediction_angular_accel: float = setting(4.0, range="(0, inf)", unit="rad/s^2",
                                              doc="the same for the turn rate (1 m/s^2 of wheel-speed difference "
                                                  "across a 0.5 m track)")
    seed: int = setting(0, range="[0, inf)")

    def check(self) -> None:
        if self.lk_window % 2 == 0:
            raise ConfigError(f"lk_window must be an odd number >= 5, got {self.lk_window}")


@dataclass
class VOEstimate:
    """The result for one frame.

    Attributes:
        index, timestamp: the frame.
        delta: (3,) motion from the previous frame (dx, dy, dtheta): pose = compose(previous pose, delta).
        covariance: (3, 3) covariance of delta (x, y, theta order; usable as a GTSAM Pose2 noise model).
        status: INIT / OK / FALLBACK / LOST.
        reference: what vision matched against (keyframe, previous frame, an earlier keyframe or none).
        method: how the correspondences were found (LK fast path, its retries, ORB descriptors).
        n_matches, n_inliers, inlier_ratio: tracked correspondences and the RANSAC inliers among them.
        rms_px: RMS inlier residual in pixels (NaN without a fit).
        is_keyframe: this frame starts a new keyframe.
        keyframe_index: index of the keyframe that `keyframe_delta` is relative to (None if there is none).
        keyframe_delta, keyframe_covariance: pose of this frame in that keyframe's frame and its covariance
            (for keyframe-to-keyframe odometry factors).
        pose: (3,) composed pose of this frame (first frame at the origin).
        keypoints: (K, 2) pixel positions of the tracked corners in this frame.
        matches: (M, 4) ref_u, ref_v, cur_u, cur_v of all tracked correspondences.
        inliers: (M,) bool RANSAC inlier mask over `matches`.
        reason: why vision failed ("" when it did not).
        fit_seconds: time spent in the robust fit (RANSAC + Kabsch), part of the step's time.
        orb_images: images whose ORB features were computed for this frame (the frame, its keyframe; ~30 ms each):
            0 on the LK fast path, also when a weak LK fit needed no descriptor check.
    """

    index: int
    timestamp: float
    delta: np.ndarray
    covariance: np.ndarray
    status: VOStatus
    reference: Reference = Reference.NONE
    method: Method = Method.NONE
    n_matches: int = 0
    n_inliers: int = 0
    inlier_ratio: float = 0.0
    rms_px: float = float("nan")
    is_keyframe: bool = False
    keyframe_index: int | None = None
    keyframe_delta: np.ndarray | None = None
    keyframe_covariance: np.ndarray | None = None
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))
    keypoints: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    matches: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    reason: str = ""
    fit_seconds: float = 0.0
    orb_images: int = 0

    @property
    def inlier_matches(self) -> np.ndarray:
        """(I, 4) the inlier correspondences, for visualisation."""
        return self.matches[self.inliers]


class _Images:
    """A frame prepared for LK: `fine` is photometrically normalised for precise single-level tracking; `coarse`
    keeps the low frequencies (gain/offset normalised only) that the coarse levels of a deep pyramid need. Only
    the retries (pyramid, phase correlation, ORB) use `coarse`, so it is computed on first use (~0.1 ms a frame
    at high rates, where most frames need none)."""

    __slots__ = ("fine", "_gray", "_coarse")

    def __init__(self, fine: np.ndarray, gray: np.ndarray | None = None, coarse: np.ndarray | None = None) -> None:
        self.fine, self._gray, self._coarse = fine, gray, coarse

    @property
    def coarse(self) -> np.ndarray:
        if self._coarse is None:
            self._coarse, self._gray = normalize(self._gray), None
        return self._coarse


@dataclass
class _Keyframe:
    index: int
    timestamp: float
    gray: _Images        # LK templates
    pts: np.ndarray      # (N, 2) float32 corner pixels
    xn: np.ndarray       # (N, 2) their undistorted normalised coordinates
    floor: np.ndarray    # (N, 2) their floor points in the keyframe's base frame
    orb: Features | None = None  # ORB features, computed when the descriptor path first needs them
    orb_dense: Features | None = None  # the dense retry's ORB features, likewise
    lattice: np.ndarray | None = None  # (K, 2) periods of its view on the floor (m; K = 0-2), when measured
    height: Height | None = None  # its camera height (None: the nominal camera_height)
    # the keyframe this one was renewed from and this one's pose in its frame (for the redundant height link;
    # cleared once the next keyframe has used it, so keyframes do not hold the whole chain)
    parent: _Keyframe | None = None
    parent_delta: np.ndarray | None = None


class VisualOdometry:
    """Frame-by-frame downward VO.

    >>> vo = VisualOdometry(camera, VOConfig())
    >>> est = vo.process(image, timestamp, fallback=(delta, cov))   # fallback optional
    >>> est.delta, est.covariance, est.status, vo.poses

    `fallback` is the motion since the previous processed frame from another source (e.g. the fused wheel/gyro
    `FusedTrajectory.relative(k-1, k)`); it seeds the LK prediction and replaces vision when vision fails.
    """

    def __init__(self, camera: CameraModel, config: VOConfig | None = None) -> None:
        if not camera.is_downward:
            raise OdometryError("VisualOdometry needs a downward camera (camera_height in camera.yaml)")
        self.camera = camera
        self.config = config or VOConfig()
        self._rng = np.random.default_rng(self.config.seed)
        self._m_per_px = camera.ground_resolution()
        self._poses: list[np.ndarray] = []
        self._covs: list[np.ndarray] = []         # covariance of each frame's delta (for re-acquisition)
        self._last_t: float | None = None
        self._now = 0.0
        self._velocity: np.ndarray | None = None  # last measured motion per second
        self._velocity_fresh = False              # it was measured on the previous frame
        self._kf: _Keyframe | None = None
        self._t_kp = np.zeros(3)                  # pose of the previous frame in the keyframe frame
        self._c_kp = np.zeros((3, 3))             # its full covariance
        self._c_kp_fit: np.ndarray | None = None  # its fit-only covariance when vision measured it from this keyframe
        self._prev_gray: _Images | None = None
        self._prev_px: np.ndarray | None = None   # tracked keyframe corners in the previous frame (inliers)
        self._failures = 0                        # consecutive frames vision could not measure
        self._fit_seconds = 0.0
        self._orb_images = 0                      # ORB extractions for the frame being processed
        self._predicted = False
        # re-acquisition: recent keyframes whose poses belong to the trajectory, and whether the current keyframe
        # chain does (a keyframe restarted after a loss starts from a guessed pose until it is re-attached)
        self._bank: list[_Keyframe] = []
        self._anchored = True
        self._unanchored_since: int | None = None
        self._frame_orb: Features | None = None   # ORB features of the frame being processed, when computed
        self._frame_orb_dense: Features | None = None  # its dense-retry ORB features, when computed
        self._dense_pass = False                  # the descriptor path matches the dense ORB sets (_dense_retry)
        self._gate: tuple[np.ndarray, np.ndarray] | None = None  # fallback motion since the previous frame + cov
        self._cv: tuple[np.ndarray, float] | None = None  # constant-velocity motion since then, bound in px
        # camera heights (odometry.height) of the previous frame and of the frame being processed
        self._height = Height(camera.camera_height)
        self._frame_height = self._height
        self._tensor_cache: tuple[_Images, np.ndarray] | None = None  # structure tensors of the last template
        self.heights = HeightTracker(camera.camera_height, self.config.height_window, self.config.height_significance,
                                     self.config.height_graded, self.config.height_noise_spread,
                                     self.config.height_random_walk_sigma, self.config.height_start_sigma)
        self.wobble = WobbleEstimate(self.config.tilt_sigma, self.config.wobble_estimate)
        self.height_links = HeightLinks(self.config.height_link_prior, self.config.height_link_gate,
                                        self.config.height_link_shrink_variance)

    # ------------------------------------------------------------------ public state
    @property
    def poses(self) -> np.ndarray:
        """(N, 3) composed poses of the frames processed so far; the first at the origin."""
        return np.array(self._poses).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self._poses)

    # ------------------------------------------------------------------ the step
    def process(self, image: np.ndarray | None, timestamp: float,
                fallback: tuple[np.ndarray, np.ndarray] | None = None) -> VOEstimate:
        """Estimate the motion since the previous frame. `image` may be None or invalid (a failed frame).

        Raises ValueError for a timestamp that does not increase (a data error, not a vision failure).
        """
        timestamp = float(timestamp)
        self._now = timestamp
        index = len(self._poses)
        self._fit_seconds = 0.0
        self._orb_images = 0
        self._frame_orb = None
        self._frame_orb_dense = None
        self._frame_height = self._height
        if self._last_t is not None and not timestamp > self._last_t:
            raise OdometryError(f"frame {index}: timestamp {timestamp!r} does not increase (previous {self._last_t!r})")
        dt = None if self._last_t is None else timestamp - self._last_t
        if fallback is not None:
            fb_delta = np.asarray(fallback[0], dtype=float).reshape(3)
            fb_cov = np.asarray(fallback[1], dtype=float).reshape(3, 3)
            if not (np.all(np.isfinite(fb_delta)) and np.all(np.isfinite(fb_cov))):
                fallback = None
            else:
                fallback = (fb_delta, fb_cov)
        try:
            gray = to_gray(image, self.camera.size)
            if contrast(gray) < self.config.min_contrast:
                raise BadImage("blank frame (no contrast)")
            reason = ""
        except BadImage as exc:
            gray, reason = None, str(exc)
        if gray is not None:
            gray = self._prepare(gray)

        if index == 0:
            self._frame_height = replace(self._frame_height, t=timestamp)   # the first keyframe's tilt time
            est = VOEstimate(index=0, timestamp=timestamp, delta=np.zeros(3), covariance=np.zeros((3, 3)),
                             status=VOStatus.INIT, reason=reason)
            if gray is not None:
                est.is_keyframe = self._start_keyframe(gray, 0, timestamp, reason_out=est)
                est.keyframe_index = 0 if est.is_keyframe else None
            self._finish(est, gray, timestamp, dt)
            return est

        pred, pred_cov = self._prediction(dt, fallback)
        self._predicted = fallback is not None or self._velocity is not None
        # descriptor motions are checked against the fallback motion when there is one (wheel odometry): a
        # constant-velocity guess says nothing at a turn, so without a fallback there is no gate
        self._gate = (pred, pred_cov * self.config.fallback_inflation) if fallback is not None else None
        self._cv = self._constant_velocity(dt)
        est = None
        if gray is not None and self._kf is not None:
            est = self._match_keyframe(gray, index, timestamp, dt, pred)
            if est is None and self._prev_px is not None and self._prev_gray is not None \
                    and self._kf.index != index - 1:
                est = self._match_previous(gray, index, timestamp, dt, pred)
            if est is None and self.config.descriptors and self.config.orb_dense_features > 0:
                est = self._dense_retry(gray, index, timestamp, dt, pred)
            if est is None:
                reason = "too few inliers"
        elif gray is not None:
            reason = "no keyframe to match (tracking was lost)"
        if gray is not None and self._should_reacquire(est, index):
            found = self._reacquire(gray, index, timestamp)
            est = found if found is not None else est
        if self._unanchored_since is not None and index - self._unanchored_since > self.config.reanchor_frames:
            # nothing earlier was seen again: accept the break and let the new keyframes serve re-acquisition
            self._anchored, self._unanchored_since = True, None
        if est is None:
            est = self._failure(index, timestamp, reason, fallback, pred, pred_cov, gray)
        self._finish(est, gray, timestamp, dt)
        return est

    # ------------------------------------------------------------------ pieces
    def _dense_retry(self, gray, index, timestamp, dt, pred) -> VOEstimate | None:
        """The keyframe, then the previous frame, again with the dense ORB sets only (no LK retries: those
        already failed). Last because it is the slowest and the likeliest to find a repeated pattern's wrong
        place: a closer reference (the previous frame) with the default set comes first."""
        self._dense_pass = True
        try:
            est = self._match_keyframe(gray, index, timestamp, dt, pred) if self._kf is not None else None
            if est is None and self._prev_px is not None and self._prev_gray is not None \
                    and (self._kf is None or self._kf.index != index - 1):
                est = self._match_previous(gray, index, timestamp, dt, pred)
            return est
        finally:
            self._dense_pass = False

    def _prepare(self, gray: np.ndarray) -> _Images:
        mode, radius = self.config.photometric, self.config.photometric_radius
        if mode == Photometric.LOCAL:
            return _Images(normalize_local(gray, radius), gray)
        if mode == Photometric.HIGHPASS:
            return _Images(highpass(gray, radius), gray)
        if mode == Photometric.GLOBAL:
            coarse = normalize(gray)
            return _Images(coarse, coarse=coarse)
        return _Images(gray, gray)

    def _prediction(self, dt: float, fallback) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        if fallback is not None:
            return fallback
        # without any motion source the guess is "no motion", flagged by self._predicted = False
        pred = self._velocity * dt if self._velocity is not None else np.zeros(3)
        return pred, np.diag([c.lost_sigma_xy ** 2, c.lost_sigma_xy ** 2, c.lost_sigma_theta ** 2])

    def _constant_velocity(self, dt: float | None) -> tuple[np.ndarray, float] | None:
        """The motion since the previous frame at the velocity vision measured on it, and the most it can be off in
        pixels (at the image edge) given `VOConfig.prediction_accel`; None when the previous frame was not measured
        by vision."""
        c = self.config
        if not self._velocity_fresh or dt is None or c.prediction_accel <= 0:
            return None
        bound = 0.5 * dt * dt * (c.prediction_accel / self._m_per_px
                                 + c.prediction_angular_accel * 0.5 * max(self.camera.size))
        return self._velocity * dt, bound

    def _holds(self, t_kc: np.ndarray, cv_kc: tuple[np.ndarray, float] | None) -> bool:
        """An LK fit t_kc agrees with the constant-velocity motion `cv_kc` (keyframe -> frame, bound in pixels)
        while that motion is itself known to within LK's capture range (half its window): the fit is where the
        robot can be, so it is no wrong settle on a self-similar floor and needs no descriptor check (at high
        frame rates; at low ones the bound exceeds the capture range)."""
        if cv_kc is None:
            return False
        c = self.config
        mean, bound = cv_kc
        if bound > 0.5 * c.lk_window:
            return False
        return self._offset_px(t_kc, mean) <= bound + c.orb_threshold_px

    def _start_keyframe(self, gray: _Images, index: int, timestamp: float,
                        reason_out: VOEstimate | None = None, t_kc: np.ndarray | None = None) -> bool:
        """Start a keyframe at this frame. `t_kc`: its pose in the current keyframe, when vision measured it from
        there (a renewal: the new keyframe's parent is the current one)."""
        c = self.config
        pts = detect_corners(gray.fine, c.max_features, c.grid, c.quality, c.min_distance, c.border,
                             c.half_resolution_detection)
        if len(pts) < c.min_features:
            if reason_out is not None and not reason_out.reason:
                reason_out.reason = f"too few corners for a keyframe ({len(pts)} < {c.min_features})"
            return False
        xn = self.camera.normalize(pts)
        parent = self._kf if t_kc is not None else None
        if c.track_height and c.height_redundant and parent is not None:
            self._frame_height = self._redundant_height(parent, gray, t_kc)
        h = self.heights.anchor(self._frame_height) if self.config.track_height else None
        if h is not None:
            self._frame_height = h
        if parent is not None:
            parent.parent = None   # its own parent has served (k-2 of this keyframe)
        self._kf = _Keyframe(index=index, timestamp=timestamp, gray=gray, pts=pts, xn=xn,
                             floor=self._floor(xn, h), orb=self._frame_orb,
                             orb_dense=self._frame_orb_dense, height=h, parent=parent,
                             parent_delta=None if t_kc is None else np.asarray(t_kc, float).copy())
        self._t_kp = np.zeros(3)
        self._c_kp = np.zeros((3, 3))
        self._c_kp_fit = np.zeros((3, 3))
        self._prev_px = pts
        if self._anchored and c.descriptors and c.reacquire_keyframes > 0:
            self._bank = (self._bank + [self._kf])[-c.reacquire_keyframes:]
        return True

    def _redundant_height(self, kf1: _Keyframe, gray: _Images, t_kc: np.ndarray) -> Height:
        """The frame's chained height (via keyframe k-1 = `kf1`) fused with its height measured against k-2 (kf1's
        parent) by LK on k-2's corners from the chained motion (odometry.height_link)."""
        kf2 = kf1.parent
        via_k1 = self._frame_height
        if kf2 is None or kf1.parent_delta is None or kf1.height is None or kf2.height is None:
            return via_k1
        t_pred = compose(kf1.parent_delta, t_kc)   # this frame in k-2's frame
        if not self._keyframe_view_overlaps(kf2, t_pred):
            return via_k1
        fit = self._track(kf2.gray, kf2.pts, kf2.xn, kf2.floor, gray, t_pred, h_ref=kf2.height)[0]
        return self.height_links.fuse(kf2.height, kf1.height, via_k1, None if fit is None else fit.height)

    def _keyframe_view_overlaps(self, kf: _Keyframe, t_kc: np.ndarray) -> bool:
        """Enough of a keyframe's corners fall inside the image at pose t_kc for a fit (cheaper than LK)."""
        return self._visible(kf, t_kc) >= self.config.min_inliers

    def _abs_height(self, height: Height | None) -> float:
        """Metres of a frame's height (the nominal camera_height without height tracking)."""
        if height is None or not self.config.track_height:
            return self.camera.camera_height
        return height.metres

    def _floor(self, xn: np.ndarray, height: Height | None) -> np.ndarray:
        """Floor points of rays for the camera at a height (nominal: `CameraModel.rays_to_floor`)."""
        h = self._abs_height(height)
        floor = self.camera.rays_to_floor(xn)
        if h == self.camera.camera_height:
            return floor
        # each viewing ray meets the floor at a distance proportional to the camera height: the same points scaled
        # about the camera's footprint (the mount), ~7x cheaper than the general `rays_to_floor_batch`
        mount = np.asarray(self.camera.mount[:2])
        return mount + (floor - mount) * (h / self.camera.camera_height)

    def _fit(self, cur_xn: np.ndarray, ref_xn: np.ndarray, cur_floor: np.ndarray, ref_floor: np.ndarray,
             threshold_px: float | None = None, min_inliers: int | None = None,
             min_ratio: float | None = None, h_ref: Height | None = None,
             weights: np.ndarray | None = None) -> RigidFit | None:
        """RANSAC + Kabsch on floor points (cur -> ref, both at the reference's height `h_ref`), then the
        tilt-aware refinement on the inliers, which also measures the current frame's height relative to it
        (`RigidFit.height`, with track_height)."""
        c = self.config
        threshold_px = c.ransac_threshold_px if threshold_px is None else threshold_px
        min_inliers = c.min_inliers if min_inliers is None else min_inliers
        min_ratio = c.min_inlier_ratio if min_ratio is None else min_ratio
        t0 = time.perf_counter()
        fit = ransac_rigid_2d(cur_floor, ref_floor, threshold_px * self._m_per_px, rng=self._rng,
                              max_iterations=c.ransac_iterations, confidence=c.ransac_confidence,
                              sigma_floor=c.pixel_sigma * self._m_per_px)
        if fit is not None and fit.n_inliers >= min_inliers and fit.inlier_ratio >= min_ratio and c.refine_tilt:
            h = self._abs_height(h_ref)
            # the height changes smoothly: the previous frame's height relative to the reference is the prior mean
            # of this one's (a zero mean would pull every measured change towards none: a biased chain)
            s_prior, tilt_prior = 0.0, None
            if c.track_height and h_ref is not None:
                s_prior = math.expm1(self._height.log_rel - h_ref.log_rel)
                if c.carry_tilt:
                    dt = self._now - self._last_t if self._last_t is not None else math.inf
                    rho = math.exp(-dt / c.wobble_time) if dt > 0 else 1.0
                    tilt_prior = np.array([*h_ref.tilt, *(rho * np.asarray(self._height.tilt))])
            tf = refine_planar_tilt(self.camera, ref_xn[fit.inliers], cur_xn[fit.inliers], fit.delta,
                                    c.tilt_sigma, c.height_sigma, c.pixel_sigma * self._m_per_px,
                                    h_ref=None if h == self.camera.camera_height else h, s_prior=s_prior,
                                    weights=None if weights is None else weights[fit.inliers],
                                    tilt_prior=tilt_prior)
            if tf is not None:
                fit.delta, fit.covariance, fit.rms, fit.sigma = tf.delta, tf.covariance, tf.rms, tf.sigma
                if c.track_height and h_ref is not None:
                    if c.height_tilt_coupling:
                        self.wobble.add(tf.params[3:7], tf.tilt_variance)
                        wobble = self.wobble.sigma if c.wobble_estimate > 0 else c.tilt_sigma
                        moved = h_ref.moved_coupled(float(tf.params[7]), tf.height_variance_data,
                                                    tf.height_tilt_gain, self._now, wobble, c.wobble_time)
                    else:
                        moved = h_ref.moved(float(tf.params[7]), tf.height_variance)
                    fit.height = replace(moved, tilt=(float(tf.params[5]), float(tf.params[6])))
        self._fit_seconds += time.perf_counter() - t0
        if fit is None or fit.n_inliers < min_inliers or fit.inlier_ratio < min_ratio:
            return None
        fit.covariance = fit.covariance * c.covariance_scale
        return fit

    def _track(self, ref_gray: _Images, ref_px: np.ndarray, ref_xn: np.ndarray, ref_floor: np.ndarray,
               gray: _Images, t_ref_cur: np.ndarray, shift: np.ndarray | None = None, levels: int | None = None,
               h_ref: Height | None = None) -> tuple[RigidFit | None, np.ndarray, np.ndarray, np.ndarray]:
        """LK from a reference frame, started at the positions predicted by the motion t_ref_cur (or by a global
        image `shift` when given); then the robust fit. A large predicted rotation is taken out of the current
        frame first (LK windows do not rotate)."""
        c = self.config
        if shift is None:
            guess_floor = (ref_floor - t_ref_cur[:2]) @ _rot(t_ref_cur[2])  # reference floor points, current frame
            guess = self.camera.floor_to_pixel(guess_floor)
        else:
            guess = ref_px + shift
        w, h = self.camera.size
        m = 2 * c.border
        visible = (guess[:, 0] > -m) & (guess[:, 0] < w + m) & (guess[:, 1] > -m) & (guess[:, 1] < h + m)
        ref_px, ref_xn, ref_floor, guess = ref_px[visible], ref_xn[visible], ref_floor[visible], guess[visible]
        fine, coarse, back = gray.fine, gray.coarse, None
        # the image content turns by about the floor rotation (exactly, for an untilted camera): skip measuring it
        # when that is far below the derotation threshold (a Kabsch fit per frame at high rates)
        if shift is None and len(guess) >= 2 and abs(wrap_angle(t_ref_cur[2])) > 0.5 * c.lk_max_rotation:
            phi = kabsch_2d(ref_px, guess)[2]   # rotation of the image content, reference -> current
            if abs(phi) > c.lk_max_rotation:
                fwd, back = _derotation(phi, (self.camera.cx, self.camera.cy))
                fine = cv2.warpAffine(fine, fwd, (w, h), flags=cv2.INTER_LINEAR, borderValue=128)
                if levels is not None and levels > c.lk_levels:
                    coarse = cv2.warpAffine(coarse, fwd, (w, h), flags=cv2.INTER_LINEAR, borderValue=128)
                guess = _affine(fwd, guess)
        if levels is not None and levels > c.lk_levels:
            # a wide capture range first, on images that keep their low frequencies, then the precise pass
            coarse_px, coarse_ok = track_lk(ref_gray.coarse, coarse, ref_px, guess, c.lk_window, levels,
                                            c.lk_iterations, c.lk_epsilon, c.lk_min_eig)
            guess = np.where(coarse_ok[:, None], coarse_px, guess)
        cur_px, ok = track_lk(ref_gray.fine, fine, ref_px, guess, c.lk_window, c.lk_levels, c.lk_iterations,
                              c.lk_epsilon, c.lk_min_eig)
        if back is not None:
            cur_px = _affine(back, cur_px)
            ok &= (cur_px[:, 0] >= 0) & (cur_px[:, 0] <= w - 1) & (cur_px[:, 1] >= 0) & (cur_px[:, 1] <= h - 1)
        ref_px, ref_xn, ref_floor, cur_px = ref_px[ok], ref_xn[ok], ref_floor[ok], cur_px[ok]
        if len(cur_px) < c.min_inliers:
            return None, ref_px, cur_px, np.zeros(len(cur_px), bool)
        cur_xn = self.camera.normalize(cur_px)
        weights = aperture_weights(self._tensors(ref_gray), ref_px) if c.aperture_weighting else None
        fit = self._fit(cur_xn, ref_xn, self._floor(cur_xn, h_ref), ref_floor, h_ref=h_ref, weights=weights)
        return fit, ref_px, cur_px, (fit.inliers if fit is not None else np.zeros(len(cur_px), bool))

    def _tensors(self, ref_gray: _Images) -> np.ndarray:
        """The structure tensors of a template image (kept for the last one: the keyframe serves many frames)."""
        if self._tensor_cache is None or self._tensor_cache[0] is not ref_gray:
            self._tensor_cache = (ref_gray, structure_tensors(ref_gray.fine, self.config.lk_window))
        return self._tensor_cache[1]

    def _measure(self, ref_gray, ref_px, ref_xn, ref_floor, gray, t_ref_cur, keyframe=None, gate=None, h_ref=None,
                 cv=None):
        """The motion from a reference frame, trying in turn: LK from the prediction (the fast path), LK with a
        deep pyramid from it, LK from the constant-velocity motion `cv` (motion reference -> frame, bound in px)
        when there is one, ORB matches against the keyframe refined by LK (any rotation, large shifts; only
        for a `keyframe`), LK from a phase-correlation shift, and without a prediction LK from no motion.
        Returns ((fit, ref_px, cur_px, inliers), Method)."""
        c = self.config
        deep = max(c.lk_levels, c.retry_levels)
        out, method = _NO_MATCH, Method.NONE
        # at high frame rates the constant-velocity motion says where the robot can be (VOConfig.cv_gate); with wheel
        # odometry only, like the constant-velocity start (without it, cv is the prediction itself)
        cv_known = self._gate is not None and cv is not None and cv[1] <= 0.5 * c.lk_window
        bounded = c.cv_gate and cv_known

        def implausible(o) -> bool:
            return bounded and o[0] is not None and not self._holds(o[0].delta, cv)

        if self._dense_pass:
            if keyframe is not None:
                out, method = self._descriptor_match(keyframe, gray, t_ref_cur, gate)
            return out, (method if out[0] is not None else Method.NONE)
        if t_ref_cur is not None:
            out, method = self._track(ref_gray, ref_px, ref_xn, ref_floor, gray, t_ref_cur, h_ref=h_ref), Method.LK
            if out[0] is None and deep > c.lk_levels:
                # a poor prediction (slip, failed frames in between): the same start with a wider capture range
                out = self._deep_track(ref_gray, ref_px, ref_xn, ref_floor, gray, t_ref_cur, deep, h_ref)
                method = Method.LK_PYRAMID
        if out[0] is None and cv_known:
            # the prediction (wheel odometry) missed by more than LK's capture range, e.g. in a wheel slip: the
            # motion vision measured on the previous frame is a start within a few pixels at high frame rates
            # (one LK pass, instead of ORB on both images). Not at low rates (without a fallback cv was the start;
            # with one, its bound is beyond LK's capture range: a start LK may settle wrongly from)
            out, method = self._track(ref_gray, ref_px, ref_xn, ref_floor, gray, cv[0], h_ref=h_ref), Method.LK
        if out[0] is not None and out[0].n_inliers < c.lk_weak_inliers and keyframe is not None and c.descriptors \
                and not self._holds(out[0].delta, cv) \
                and out[0].n_inliers < c.lk_weak_visible_fraction * self._visible(keyframe, out[0].delta):
            # few corners tracked from the prediction: at a low frame rate the prediction (constant velocity) is a
            # guess, and on a self-similar floor LK can settle at a wrong place with 20-35 consistent corners
            # (seen at lane turns on real grass and carpet photographs). The descriptor path starts LK on the same
            # keyframe corners from where the ORB matches put them; when the two places differ, the start that
            # tracks more of them wins (when they agree, LK's own fit stands: the frame is not a descriptor frame)
            alt, alt_method = _NO_MATCH, Method.NONE
            if bounded:
                # the weak fit is not where the robot can be: LK from the constant-velocity motion first (one LK
                # pass; on a periodic floor the descriptors match the copy of the view as well as the place)
                alt, alt_method = self._track(ref_gray, ref_px, ref_xn, ref_floor, gray, cv[0], h_ref=h_ref), Method.LK
                if implausible(alt):
                    alt = _NO_MATCH
            if alt[0] is None or alt[0].n_inliers <= out[0].n_inliers:
                # ... and when that does not track more corners, the descriptor check as without the bound
                orb, orb_method = self._descriptor_match(keyframe, gray, t_ref_cur, gate)
                if orb[0] is not None and not implausible(orb) \
                        and (alt[0] is None or orb[0].n_inliers > alt[0].n_inliers):
                    alt, alt_method = orb, orb_method
            if alt[0] is not None and alt[0].n_inliers > out[0].n_inliers \
                    and not self._same_place(alt[0].delta, out[0].delta):
                out, method = alt, alt_method
        if out[0] is None and keyframe is not None and c.descriptors:
            out, method = self._descriptor_match(keyframe, gray, t_ref_cur, gate)
            if implausible(out):
                out = _NO_MATCH
        if out[0] is None and c.coarse_retry:
            shift, response = coarse_shift(ref_gray.coarse, gray.coarse)
            if response > c.coarse_min_response:
                out = self._track(ref_gray, ref_px, ref_xn, ref_floor, gray, np.zeros(3), shift=shift, levels=deep,
                                  h_ref=h_ref)
                method = Method.LK_SHIFT
                # the correlation peak of a periodic floor can be a copy of the view one period away: with wheel
                # odometry, the motion must be where the robot can be (like a descriptor motion)
                if implausible(out) or (out[0] is not None and c.shift_gate and gate is not None
                                        and t_ref_cur is not None and not self._in_gate(out[0], t_ref_cur, gate[1])):
                    out = _NO_MATCH
                if out[0] is not None and c.alias_guard and gate is not None and t_ref_cur is not None:
                    # ... and inside the gate it may still be a copy while the place is another (VOConfig.alias_guard)
                    ref = keyframe if keyframe is not None else _Keyframe(
                        index=-1, timestamp=0.0, gray=ref_gray, pts=ref_px, xn=ref_xn, floor=ref_floor, height=h_ref)
                    share = out[0].n_inliers / max(self._visible(ref, out[0].delta), 1)
                    out = self._dealias(ref, gray, out, share, t_ref_cur, gate, c.orb_confirm_fraction)
        if out[0] is None and t_ref_cur is None:
            out = self._deep_track(ref_gray, ref_px, ref_xn, ref_floor, gray, np.zeros(3), deep, h_ref)
            method = Method.LK_PYRAMID
        return out, (method if out[0] is not None else Method.NONE)

    def _capture_range(self, levels: int) -> float:
        """Pixels from its start that pyramidal LK with `levels` levels above the image can reach: half the window
        at the top level, refined level by level (Bouguet's d_max (2^(L+1) - 1); 112 px for a 15 px window and 3
        levels). A result farther off was not reached by tracking from the start: on a periodic floor, a copy."""
        return 0.5 * self.config.lk_window * (2 ** (levels + 1) - 1)

    def _offset_px(self, a: np.ndarray, b: np.ndarray) -> float:
        """How far apart two motions put the image: their translation in pixels plus the rotation at the image edge."""
        d = a - b
        return math.hypot(d[0], d[1]) / self._m_per_px + abs(wrap_angle(d[2])) * 0.5 * max(self.camera.size)

    def _deep_track(self, ref_gray, ref_px, ref_xn, ref_floor, gray, start: np.ndarray, levels: int, h_ref):
        """LK with a deep pyramid from the motion `start`; its result only within the pyramid's capture range."""
        out = self._track(ref_gray, ref_px, ref_xn, ref_floor, gray, start, levels=levels, h_ref=h_ref)
        if out[0] is not None and self.config.retry_capture_check \
                and self._offset_px(out[0].delta, start) > self._capture_range(levels):
            return _NO_MATCH
        return out

    def _orb(self, images: _Images, dense: bool = False) -> Features:
        c = self.config
        self._orb_images += 1
        if dense:
            return orb_features(images.coarse, c.orb_dense_features, c.orb_dense_fast_threshold, c.border)
        return orb_features(images.coarse, c.orb_features, c.orb_fast_threshold, c.border)

    def _descriptor_match(self, kf: _Keyframe, gray: _Images, t_pred: np.ndarray | None,
                          gate: tuple[np.ndarray, np.ndarray] | None, confirm: bool = False):
        """ORB matches keyframe -> frame, the rigid fit on their floor points, then LK on the keyframe's corners
        started from that motion (sub-pixel). `gate` = (predicted motion, covariance): a fit outside it is
        rejected (a repeated pattern can match the wrong place). With `confirm`, only LK-confirmed motions count
        (re-acquisition: the keyframe may be any of several, so a wrong place is likelier). In the dense pass (see
        `process`) the denser ORB sets are matched instead, and their motions must be confirmed by LK."""
        if not self._dense_pass:
            if kf.orb is None:
                kf.orb = self._orb(kf.gray)
            if self._frame_orb is None:
                self._frame_orb = self._orb(gray)
            return self._orb_hypotheses(kf, kf.orb, self._frame_orb, gray, t_pred, gate, confirm, strong_alone=True)
        if kf.orb_dense is None:
            kf.orb_dense = self._orb(kf.gray, dense=True)
        if self._frame_orb_dense is None:
            self._frame_orb_dense = self._orb(gray, dense=True)
        # many more weak corners: more chance of a consistent wrong consensus on a repeated texture, so no
        # unconfirmed ORB-only motion from this set
        return self._orb_hypotheses(kf, kf.orb_dense, self._frame_orb_dense, gray, t_pred, gate, confirm,
                                    strong_alone=False)

    def _orb_hypotheses(self, kf: _Keyframe, kf_orb: Features, frame_orb: Features, gray: _Images,
                        t_pred: np.ndarray | None, gate: tuple[np.ndarray, np.ndarray] | None, confirm: bool,
                        strong_alone: bool):
        """The RANSAC consensus sets of one pair of ORB sets, tried in turn until LK confirms one."""
        c = self.config
        none = (_NO_MATCH, Method.NONE)
        ia, ib = match_features(kf_orb, frame_orb, c.orb_ratio)
        if len(ia) < c.orb_min_inliers:
            return none
        ref_px, cur_px = kf_orb.pts[ia], frame_orb.pts[ib]
        ref_xn, cur_xn = self.camera.normalize(ref_px), self.camera.normalize(cur_px)
        ref_fl, cur_fl = self._floor(ref_xn, kf.height), self._floor(cur_xn, kf.height)
        # a repeated texture (or any pattern that the ORB tests cannot tell apart) can give a consistent but wrong
        # motion: each RANSAC winner must be confirmed by LK on the keyframe's corners, and the next consensus
        # among the remaining matches is tried too; of the places where LK tracks enough of the corners it puts
        # in view, the one with the most LK inliers wins (VOConfig.orb_hypothesis_evidence; seen on render_floor:
        # a wrong place with 40 of 88 corners tracked came first and the true one, 45 of 71, second). Only a
        # strong ORB consensus stands on its own.
        left = np.arange(len(ia))
        need = c.reacquire_min_fraction if confirm else c.orb_confirm_fraction
        best, best_share, best_score, strong, outside = None, 0.0, 0.0, None, None
        for _ in range(c.orb_hypotheses):
            if len(left) < c.orb_min_inliers:
                break
            fit = self._fit(cur_xn[left], ref_xn[left], cur_fl[left], ref_fl[left], c.orb_threshold_px,
                            c.orb_min_inliers, c.orb_min_inlier_ratio * len(ia) / len(left), h_ref=kf.height)
            if fit is None:
                break
            if gate is None or t_pred is None or self._in_gate(fit, t_pred, gate[1]):
                refined = self._track(kf.gray, kf.pts, kf.xn, kf.floor, gray, fit.delta, h_ref=kf.height)
                share = 0.0 if refined[0] is None else refined[0].n_inliers / max(self._visible(kf, fit.delta), 1)
                score = share if c.orb_hypothesis_evidence == "share" else \
                    (0.0 if refined[0] is None else refined[0].n_inliers)
                if share >= need and score > best_score:
                    best, best_share, best_score = refined, share, score
                if strong is None and strong_alone and not confirm and fit.n_inliers >= c.orb_strong_inliers \
                        and fit.n_inliers >= c.orb_strong_ratio * len(ia):
                    strong = (fit, ref_px[left], cur_px[left], fit.inliers)
            elif outside is None:
                outside = (fit, ref_px[left], cur_px[left], fit.inliers)
            left = left[~fit.inliers]
        if best is not None:
            best = self._dealias(kf, gray, best, best_share, t_pred, gate, need)
            return (best, Method.ORB_LK) if best[0] is not None else none
        if strong is not None:
            strong = self._dealias(kf, gray, strong, need, t_pred, gate, need)
            return (strong, Method.ORB) if strong[0] is not None else none
        if outside is not None:
            # a copy of the view outside the gate: on a periodic floor the place itself may be a lattice step away
            found = self._dealias(kf, gray, outside, need, t_pred, gate, need, inside=False)
            return (found, Method.ORB_LK) if found[0] is not None else none
        return none

    def _lattice(self, kf: _Keyframe) -> np.ndarray:
        """The periods of a keyframe's view (odometry.lattice.view_lattice), measured once per keyframe."""
        if kf.lattice is None:
            c = self.config
            if kf.orb is None:
                kf.orb = self._orb(kf.gray)
            feats = kf.orb
            if len(feats) < c.orb_min_inliers:
                kf.lattice = np.zeros((0, 2))
                return kf.lattice
            kf.lattice = view_lattice(self._floor(self.camera.normalize(feats.pts), kf.height), feats.desc,
                                      tol=c.orb_threshold_px * self._m_per_px, min_step=c.lk_window * self._m_per_px,
                                      min_count=c.orb_min_inliers)
        return kf.lattice

    def _dealias(self, kf: _Keyframe, gray: _Images, out, share: float, t_pred: np.ndarray | None,
                 gate: tuple[np.ndarray, np.ndarray] | None, need: float, inside: bool = True):
        """`out`, a descriptor or phase-correlation motion from keyframe `kf` (inside the gate, or with `inside`
        False outside it), or the copy of it one or more lattice steps away that the prediction makes likeliest,
        or no motion (_NO_MATCH) when no copy is likely enough (VOConfig.alias_guard). A copy inside the gate is
        confirmed when LK started there stays there and tracks a comparable share of the corners it puts in
        view, ruled out when LK does not, and stays possible, unconfirmable, when too few corners are in view."""
        c = self.config
        if not c.alias_guard or gate is None or t_pred is None or out[0] is None:
            return out if inside else _NO_MATCH
        lattice = self._lattice(kf)
        if len(lattice) == 0:
            return out if inside else _NO_MATCH
        a = out[0].delta
        # the likelihood of a copy is the prediction's own (the gate's covariance without its fallback_inflation,
        # which is a margin for the gate, not the wheel odometry's word); the gate still bounds the copies tried
        info = np.linalg.inv(self._gate_covariance(gate[1] / max(c.fallback_inflation, 1.0), out[0].covariance))
        gate_info = np.linalg.inv(self._gate_covariance(gate[1], out[0].covariance))

        def d2(t: np.ndarray, m: np.ndarray = info) -> float:
            e = t - t_pred
            e[2] = wrap_angle(e[2])
            return float(e @ m @ e)

        # the lattice steps that bring `a` nearest the prediction, and their neighbours
        k0 = np.linalg.lstsq(lattice.T, (t_pred - a)[:2], rcond=None)[0]
        ranges = [range(int(math.floor(k)) - 2, int(math.floor(k)) + 4) for k in k0]
        grid = np.array(np.meshgrid(*ranges, indexing="ij")).reshape(len(lattice), -1).T
        pool = [(out, d2(a))] if inside else []
        copies = []
        for k in grid:
            if k.any():
                t = a.copy()
                t[:2] += k @ lattice
                if d2(t, gate_info) <= c.prediction_gate ** 2:
                    copies.append((d2(t), t))
        # a copy whose likelihood is below 1 % of what the decision leaves to the others cannot change it: not tested
        e2_min = min([e2 for e2, _ in copies] + [p[1] for p in pool], default=0.0)
        negligible = e2_min - 2 * math.log(0.01 * max(1 - c.alias_confidence, 1e-12))
        for e2, t in sorted(copies, key=lambda x: x[0]):
            if e2 > negligible:
                break
            if self._visible(kf, t) < c.min_inliers:
                # vision cannot tell whether the place is there (it hardly overlaps the keyframe): possible
                pool.append((_NO_MATCH, e2))
                continue
            copy = self._track(kf.gray, kf.pts, kf.xn, kf.floor, gray, t, h_ref=kf.height)
            if copy[0] is None or self._offset_px(copy[0].delta, t) > 0.5 * c.lk_window \
                    or self._same_place(copy[0].delta, a):
                continue
            copy_share = copy[0].n_inliers / max(self._visible(kf, copy[0].delta), 1)
            if copy_share >= max(need, c.alias_support * share):
                pool.append((copy, d2(copy[0].delta)))
        if not pool:
            return _NO_MATCH
        if len(pool) == 1:
            return pool[0][0]
        e2 = np.array([p[1] for p in pool])
        post = np.exp(-0.5 * (e2 - e2.min()))
        post /= post.sum()
        i = int(np.argmax(post))
        return pool[i][0] if post[i] >= c.alias_confidence else _NO_MATCH

    def _same_place(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Two motions within the ORB inlier distance of each other, at the image centre and at its edge."""
        tol = self.config.orb_threshold_px
        d = a - b
        return bool(math.hypot(d[0], d[1]) / self._m_per_px <= tol
                    and abs(wrap_angle(d[2])) * 0.5 * max(self.camera.size) <= tol)

    def _visible(self, kf: _Keyframe, t_kc: np.ndarray) -> int:
        """How many of the keyframe's corners the motion t_kc puts inside the current image."""
        px = self.camera.floor_to_pixel((kf.floor - t_kc[:2]) @ _rot(t_kc[2]))
        w, h = self.camera.size
        return int(((px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)).sum())

    def _stay_in_view(self, px: np.ndarray, step: np.ndarray, count: int) -> bool:
        """At least `count` of the pixels `px` stay in the image when the view moves once more by `step` (the
        motion since the previous frame): those farther from the border than that motion's image shift (1.5x the
        central ground resolution's: lens distortion, tilt), plus its rotation at the image corners. A lower bound
        on `_visible` at the next frame in a few array operations (projecting every keyframe corner costs ~100 us
        per frame at high rates, where it almost never renews the keyframe)."""
        w, h = self.camera.size
        d = 1.5 * math.hypot(step[0], step[1]) / self._m_per_px + abs(step[2]) * 0.5 * math.hypot(w, h) + 2.0
        inside = (px[:, 0] >= d) & (px[:, 0] < w - 1 - d) & (px[:, 1] >= d) & (px[:, 1] < h - 1 - d)
        return int(inside.sum()) >= count

    def _in_gate(self, fit: RigidFit, t_pred: np.ndarray, cov: np.ndarray) -> bool:
        c = self.config
        e = fit.delta - t_pred
        e[2] = wrap_angle(e[2])
        s = self._gate_covariance(cov, fit.covariance)
        return float(e @ np.linalg.solve(s, e)) <= c.prediction_gate ** 2

    def _gate_covariance(self, cov: np.ndarray, fit_cov: np.ndarray) -> np.ndarray:
        """A motion's disagreement with a prediction of covariance `cov`: both covariances and the matcher's
        inlier distance (and 0.01 rad) as slack."""
        return cov + fit_cov + np.diag([(self.config.orb_threshold_px * self._m_per_px) ** 2] * 2 + [1e-4])

    def _model_covariance(self, dt: float, motion: np.ndarray) -> np.ndarray:
        """What the planar model misses between two frames dt apart: tilt/height wobble (see VOConfig)."""
        c = self.config
        frac = 2.0 * (1.0 - math.exp(-dt / c.wobble_time)) if c.wobble_time > 0 else 2.0
        h = self.camera.camera_height
        shift2 = (h * c.tilt_sigma) ** 2 + (c.height_sigma / h) ** 2 * float(motion[0] ** 2 + motion[1] ** 2)
        return frac * np.diag([shift2, shift2, (c.tilt_rotation_coupling * c.tilt_sigma) ** 2])

    def _match_keyframe(self, gray, index, timestamp, dt, pred) -> VOEstimate | None:
        kf = self._kf
        t_kc_pred = compose(self._t_kp, pred) if self._predicted else None
        gate = None if self._gate is None else (compose(self._t_kp, self._gate[0]), self._c_kp + self._gate[1])
        cv = None if self._cv is None else (compose(self._t_kp, self._cv[0]), self._cv[1])
        (fit, ref_px, cur_px, inl), method = self._measure(kf.gray, kf.pts, kf.xn, kf.floor, gray, t_kc_pred,
                                                           keyframe=kf, gate=gate, h_ref=kf.height, cv=cv)
        if fit is None:
            return None
        tilt = self.config.refine_tilt  # the fit's covariance already covers the wobble
        c_kc = fit.covariance if tilt else fit.covariance + self._model_covariance(timestamp - kf.timestamp,
                                                                                    fit.delta)
        if self._c_kp_fit is not None and not tilt:
            # previous frame measured from the same keyframe: their wobble errors are mostly shared and cancel
            delta, cov = between_with_covariance(self._t_kp, self._c_kp_fit, fit.delta, fit.covariance)
            cov = cov + self._model_covariance(dt, delta)
        else:
            delta, cov = between_with_covariance(self._t_kp, self._c_kp, fit.delta, c_kc)
        est = self._estimate(index, timestamp, delta, cov, Reference.KEYFRAME, fit, ref_px, cur_px, method)
        est.keyframe_index, est.keyframe_delta, est.keyframe_covariance = kf.index, fit.delta, c_kc
        self._t_kp, self._c_kp, self._c_kp_fit = fit.delta, c_kc, fit.covariance
        self._prev_px = cur_px[inl]
        # keep or renew the keyframe
        c = self.config
        n_in = fit.n_inliers
        # a frame that needed descriptors (or a shift search) is far from the keyframe: renew, so the next frame is
        # matched to a close keyframe (at a low rate the next one would barely overlap); and renew when the next
        # frame, moving on as this one did, would see too few of the keyframe's corners. A deep-pyramid LK retry
        # alone does not renew: at high rates it only means a poor constant-velocity prediction, and renewing there
        # chained 1.7x the keyframes (100 m carpet: 524 vs 317, VO end error 14.0 vs 5.8 cm)
        renew = (method not in (Method.LK, Method.LK_PYRAMID) or n_in < c.keyframe_min_inliers
                 or n_in < c.keyframe_min_fraction * len(kf.pts) or abs(fit.delta[2]) > c.keyframe_max_rotation
                 or (not self._stay_in_view(cur_px[inl], delta, c.keyframe_min_inliers)
                     and self._visible(kf, compose(fit.delta, delta)) < c.keyframe_min_inliers))
        if renew and self._start_keyframe(gray, index, timestamp, t_kc=fit.delta):
            est.is_keyframe = True
        return est

    def _match_previous(self, gray, index, timestamp, dt, pred) -> VOEstimate | None:
        c = self.config
        prev_px = self._prev_px
        prev_xn = self.camera.normalize(prev_px)
        h = self._height
        (fit, ref_px, cur_px, _), method = self._measure(self._prev_gray, prev_px, prev_xn, self._floor(prev_xn, h),
                                                         gray, pred if self._predicted else None, gate=self._gate,
                                                         h_ref=h, cv=self._cv)
        if fit is None and c.descriptors:
            # descriptors against the previous frame, with corners of its own: the keyframe corners it tracked sit
            # where it overlapped the keyframe, often not where it overlaps this frame (a low rate)
            pts = detect_corners(self._prev_gray.fine, c.max_features, c.grid, c.quality, c.min_distance, c.border,
                                 c.half_resolution_detection)
            xn = self.camera.normalize(pts)
            prev = _Keyframe(index=index - 1, timestamp=timestamp - dt, gray=self._prev_gray, pts=pts, xn=xn,
                             floor=self._floor(xn, h), height=h)
            gate = None if self._gate is None else self._gate
            (fit, ref_px, cur_px, _), method = self._descriptor_match(prev, gray, pred if self._predicted else None,
                                                                      gate)
        if fit is None:
            return None
        cov = fit.covariance if self.config.refine_tilt else fit.covariance + self._model_covariance(dt, fit.delta)
        est = self._estimate(index, timestamp, fit.delta, cov, Reference.PREVIOUS, fit, ref_px, cur_px, method)
        # the keyframe could not be tracked: this frame replaces it
        if self._start_keyframe(gray, index, timestamp):
            est.is_keyframe = True
            est.keyframe_index = index
            est.keyframe_delta, est.keyframe_covariance = np.zeros(3), np.zeros((3, 3))
        else:
            self._kf = None
        return est

    def _should_reacquire(self, est: VOEstimate | None, index: int) -> bool:
        """Match against the recent keyframes when vision failed, or while the keyframe chain restarted after a
        loss is not yet re-attached to them."""
        c = self.config
        if not (c.descriptors and c.reacquire_keyframes > 0 and self._bank):
            return False
        if est is None:
            return True
        return self._unanchored_since is not None and index - self._unanchored_since <= c.reanchor_frames

    def _chain(self, start: int) -> tuple[np.ndarray, np.ndarray]:
        """Pose of the previous frame in frame `start`'s frame, and its covariance (the deltas in between)."""
        t, cov = np.zeros(3), np.zeros((3, 3))
        for k in range(start + 1, len(self._poses)):
            t, cov = compose_with_covariance(t, cov, between(self._poses[k - 1], self._poses[k]), self._covs[k])
        return t, cov

    def _reacquire(self, gray: _Images, index: int, timestamp: float) -> VOEstimate | None:
        """Re-acquisition: ORB matches against the recent keyframes whose poses are on the trajectory (newest
        first). A match places this frame relative to that keyframe, so the trajectory continues from where it
        was, whatever was guessed in between; the frame starts an anchored keyframe."""
        for kf in reversed(self._bank):
            if kf is self._kf and self._anchored:
                continue  # already tried by the keyframe path
            t_jp, c_jp = self._chain(kf.index)
            gate = None
            if self._gate is not None:
                gate = (compose(t_jp, self._gate[0]), c_jp + self._gate[1])
            (fit, ref_px, cur_px, inl), method = self._descriptor_match(kf, gray, None if gate is None else gate[0],
                                                                        gate, confirm=True)
            if fit is None:
                continue
            delta, cov = between_with_covariance(t_jp, c_jp, fit.delta, fit.covariance)
            est = self._estimate(index, timestamp, delta, cov, Reference.REACQUIRED, fit, ref_px, cur_px, method)
            est.keyframe_index, est.keyframe_delta, est.keyframe_covariance = kf.index, fit.delta, fit.covariance
            self._kf, self._t_kp, self._c_kp, self._c_kp_fit = kf, fit.delta, fit.covariance, fit.covariance
            self._prev_px = cur_px[inl]
            self._anchored, self._unanchored_since = True, None
            if self._start_keyframe(gray, index, timestamp):
                est.is_keyframe = True
            return est
        return None

    def _estimate(self, index, timestamp, delta, cov, ref, fit: RigidFit, ref_px, cur_px,
                  method: Method = Method.LK) -> VOEstimate:
        if fit.height is not None:
            self._frame_height = fit.height
        return VOEstimate(index=index, timestamp=timestamp, delta=delta, covariance=cov, status=VOStatus.OK,
                          reference=ref, method=method, n_matches=len(cur_px), n_inliers=fit.n_inliers,
                          inlier_ratio=fit.inlier_ratio, rms_px=fit.rms / self._m_per_px,
                          keypoints=np.asarray(cur_px, dtype=float),
                          matches=np.column_stack([ref_px, cur_px]).astype(float), inliers=fit.inliers)

    def _failure(self, index, timestamp, reason, fallback, pred, pred_cov, gray) -> VOEstimate:
        c = self.config
        if fallback is not None:
            status = VOStatus.FALLBACK
            cov = pred_cov * c.fallback_inflation
        else:
            status = VOStatus.LOST
            cov = pred_cov
        floor = (c.pixel_sigma * self._m_per_px) ** 2
        cov = cov + np.diag([floor, floor, 1e-8])  # never a zero covariance, even for a zero motion
        est = VOEstimate(index=index, timestamp=timestamp, delta=np.asarray(pred, float).copy(), covariance=cov,
                         status=status, reason=reason)
        self._failures += 1
        if self._kf is not None:
            # carry the keyframe through the failure: the next good frame may still see it (a blurred or corrupt
            # frame should not end a good keyframe)
            self._t_kp, self._c_kp = compose_with_covariance(self._t_kp, self._c_kp, est.delta, cov)
            self._c_kp_fit = None
            self._prev_px = None
            if not self._keyframe_in_view(self._t_kp) or (gray is not None
                                                         and self._failures > c.max_failures_before_reset):
                self._kf = None
        if gray is not None and self._kf is None:
            # a usable frame and nothing to match it to: restart tracking from it. Its pose is a guess, so its
            # keyframes stay out of the re-acquisition bank until a frame re-attaches them
            if self._bank:
                self._anchored = False
                if self._unanchored_since is None:
                    self._unanchored_since = index
            if self._start_keyframe(gray, index, timestamp, reason_out=est):
                est.is_keyframe = True
        if self._kf is not None:
            est.keyframe_index = self._kf.index
            est.keyframe_delta, est.keyframe_covariance = self._t_kp.copy(), self._c_kp.copy()
        return est

    def _keyframe_in_view(self, t_kc: np.ndarray) -> bool:
        kf = self._kf
        pts = (kf.floor - t_kc[:2]) @ _rot(t_kc[2])
        px = self.camera.floor_to_pixel(pts)
        w, h = self.camera.size
        inside = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
        return inside.sum() >= self.config.min_inliers

    def _finish(self, est: VOEstimate, gray, timestamp: float, dt: float | None) -> None:
        est.fit_seconds = self._fit_seconds
        est.orb_images = self._orb_images
        prev = self._poses[-1] if self._poses else np.zeros(3)
        est.pose = compose(prev, est.delta) if self._poses else np.zeros(3)
        self._poses.append(est.pose)
        self._covs.append(np.asarray(est.covariance, float))
        self._height = self._frame_height
        if self.config.track_height:
            self.heights.observe(timestamp, self._height)
        self._velocity_fresh = False
        if est.status == VOStatus.OK:
            self._failures = 0
            if dt and est.reference != Reference.REACQUIRED:  # a re-attachment jump is no velocity
                self._velocity = est.delta / dt
                self._velocity_fresh = True
        self._last_t = timestamp
        self._prev_gray = gray


_NO_MATCH = (None, np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, bool))


def _derotation(phi: float, centre: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """2x3 affine maps that rotate pixels by -phi about `centre` (forward) and back."""
    def rot(a: float) -> np.ndarray:
        c, s = math.cos(a), math.sin(a)
        r = np.array([[c, -s], [s, c]])
        ctr = np.asarray(centre, float)
        return np.column_stack([r, ctr - r @ ctr])
    return rot(-phi), rot(phi)


def _affine(m: np.ndarray, pts: np.ndarray) -> np.ndarray:
    return np.asarray(pts, float) @ m[:, :2].T + m[:, 2]


def _rot(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


# ---------------------------------------------------------------------------------------------------- batch

@dataclass
class VOTrajectory:
    """Batch result of `run_visual_odometry` (small per-frame arrays only: memory stays bounded).

    poses (N, 3) start at the origin; deltas (N, 3) with deltas[0] = 0; covariances (N, 3, 3) of the deltas;
    status (N,) VOStatus values; method (N,) Method values (how each frame was matched); vo_seconds /
    image_seconds (N,) time of the VO step and of fetching the image; orb_images (N,) ORB extractions per frame
    (see `VOEstimate.orb_images`).
    """

    timestamps: np.ndarray
    poses: np.ndarray
    deltas: np.ndarray
    covariances: np.ndarray
    status: list
    n_matches: np.ndarray
    n_inliers: np.ndarray
    inlier_ratio: np.ndarray
    rms_px: np.ndarray
    is_keyframe: np.ndarray
    reference: list
    reason: list
    vo_seconds: np.ndarray
    image_seconds: np.ndarray
    method: list = field(default_factory=list)
    orb_images: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.timestamps)

    def csv_rows(self) -> list[str]:
        """`odometry.csv` lines: header then one row per frame."""
        rows = ["index,timestamp,status,reference,dx,dy,dtheta,sigma_x,sigma_y,sigma_theta,n_matches,n_inliers,"
                "inlier_ratio,rms_px,is_keyframe,vo_ms,reason,method,orb_images"]
        orb = np.zeros(len(self.timestamps), int) if self.orb_images is None else self.orb_images
        for i in range(len(self.timestamps)):
            d, cv = self.deltas[i], self.covariances[i]
            sig = np.sqrt(np.maximum(np.diag(cv), 0.0))
            reason = self.reason[i].replace(",", ";").replace("\n", " ")
            rows.append(f"{i},{self.timestamps[i]:.6f},{self.status[i].value},{self.reference[i].value},"
                        f"{d[0]:.9f},{d[1]:.9f},{d[2]:.9f},{sig[0]:.3e},{sig[1]:.3e},{sig[2]:.3e},"
                        f"{self.n_matches[i]},{self.n_inliers[i]},{self.inlier_ratio[i]:.4f},{self.rms_px[i]:.4f},"
                        f"{int(self.is_keyframe[i])},{self.vo_seconds[i] * 1e3:.3f},{reason},"
                        f"{(self.method[i] if i < len(self.method) else Method.NONE).value},{int(orb[i])}")
        return rows


def run_visual_odometry(camera: CameraModel, timestamps: np.ndarray, get_image: Callable[[int], np.ndarray | None],
                        config: VOConfig | None = None, fallback: Callable[[int], tuple] | None = None,
                        on_frame: Callable[[VOEstimate], None] | None = None) -> VOTrajectory:
    """Run the VO over a whole sequence.

    Args:
        camera: the downward camera.
        timestamps: (N,) frame times.
        get_image: index -> image (BGR or grey). Exceptions it raises for a single frame (OSError, ValueError)
            make that frame a failed frame, like a corrupt image.
        config: VO parameters.
        fallback: optional index -> (delta, covariance) of the motion from frame index-1 to index, e.g.
            `FusedTrajectory.relative(i - 1, i)` from `odometry.fusion.fuse_wheel_gyro`.
        on_frame: optional callback receiving each VOEstimate (e.g. for visualisation).
    """
    ts = np.asarray(timestamps, dtype=float).reshape(-1)
    vo = VisualOdometry(camera, config)
    n = len(ts)
    deltas = np.zeros((n, 3))
    covs = np.zeros((n, 3, 3))
    n_m = np.zeros(n, int)
    n_i = np.zeros(n, int)
    ratio = np.zeros(n)
    rms = np.full(n, np.nan)
    kf = np.zeros(n, bool)
    t_vo = np.zeros(n)
    t_img = np.zeros(n)
    orb = np.zeros(n, int)
    status, ref, reason, method = [], [], [], []
    for i in range(n):
        t0 = time.perf_counter()
        try:
            img = get_image(i)
        except (OSError, ValueError) as exc:
            img = None
            err = f"image could not be read: {exc}"
        else:
            err = ""
        t1 = time.perf_counter()
        fb = fallback(i) if (fallback is not None and i > 0) else None
        est = vo.process(img, ts[i], fallback=fb)
        t2 = time.perf_counter()
        if err and not est.reason.startswith("image could not"):
            est.reason = err
        deltas[i], covs[i] = est.delta, est.covariance
        n_m[i], n_i[i], ratio[i], rms[i], kf[i] = est.n_matches, est.n_inliers, est.inlier_ratio, est.rms_px, \
            est.is_keyframe
        status.append(est.status)
        ref.append(est.reference)
        method.append(est.method)
        orb[i] = est.orb_images
        reason.append(est.reason)
        t_img[i], t_vo[i] = t1 - t0, t2 - t1
        if on_frame is not None:
            on_frame(est)
    return VOTrajectory(timestamps=ts, poses=vo.poses, deltas=deltas, covariances=covs, status=status,
                        n_matches=n_m, n_inliers=n_i, inlier_ratio=ratio, rms_px=rms, is_keyframe=kf,
                        reference=ref, reason=reason, vo_seconds=t_vo, image_seconds=t_img, method=method,
                        orb_images=orb)
