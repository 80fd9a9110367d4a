"""`PipelineConfig`: every tunable of a SLAM run in one place, with sane defaults, loadable from YAML or TOML.

Sections reuse each package's own parameter classes (VOConfig, FusionConfig, DatabaseParams, GraphParams), so a
config file can set anything those expose:

    vo:        {max_features: 300}
    loops:     {mode: 5, database: {confirmations: 2}}      # or {recognizer: vocab, vocab: {min_inliers: 25}}
    graph:     {robust: gnc}
    keyframes: {footprint_fraction: 0.25}   # or {distance: 0.1} in metres

Loading, dumping, presets, `--set`-style overrides and the range of every value come from
`odometry.shared.config.Config`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from graph.params import GraphParams
from loops.cdvs.params import MODES
from loops.loop_detector import DatabaseParams
from odometry.fusion import FusionConfig
from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, ConfigError, setting
from odometry.vo import VOConfig
from vslam.pipeline.motion_gate import MotionGateParams


@dataclass(frozen=True)
class KeyframePolicy(Config):
    """When a frame becomes a loop keyframe (and a pose-graph node): after the robot moved or turned enough."""

    # spacing in footprints, not metres: a metric spacing made every frame a keyframe for a camera 40 m up (a 40 m
    # footprint) and skipped a 5 cm camera's whole footprint. Measured along the direction of travel, since the
    # overlap of two views a distance d apart along it is (L - d) / (L + d) for the footprint's length L that way.
    # 0.42 L: consecutive keyframes overlap by J >= 0.41, a revisit anywhere along the track has a stored keyframe
    # within 0.21 L (J >= 0.65, well above the 0.33 that defines a loop); on the default camera driving along its
    # 0.655 m footprint length it is 0.275 m, the mean gap of the former "first frame past 0.25 m" at 1 m/s and
    # 20 fps, so floor runs keep their keyframes; under a drone's 40 m footprint it is 17 m, so 0.14 Hz frames
    # 14 m apart all stay keyframes
    footprint_fraction: float = setting(0.42, range="(0, inf)",
                                        unit="footprint length along the direction of travel",
                                        doc="travelled since the last keyframe")
    distance: float | None = setting(None, range="(0, inf)", unit="m",
                                     doc="travelled since the last keyframe, in metres instead of footprint_fraction "
                                         "(None: footprint_fraction)")
    angle_deg: float = setting(20.0, range="(0, inf)", unit="deg", doc="or turned")
    max_frames: int = setting(60, range="[1, inf)",
                              doc="or frames elapsed (keeps the graph connected when standing still)")

    def spacing(self, camera: CameraModel, direction: tuple[float, float] | None = None) -> float:
        """Metres travelled between keyframes for this camera moving along `direction` (base frame; None: the
        footprint's shorter extent along the base axes): `distance`, else the footprint fraction."""
        if self.distance is not None:
            return float(self.distance)
        if camera.camera_height is None:
            raise ConfigError("keyframes.footprint_fraction needs the camera height (camera.yaml camera_height); "
                              "set keyframes.distance in metres instead")
        poly = camera.footprint()
        if direction is None:
            length = float(min(np.ptp(poly[:, 0]), np.ptp(poly[:, 1])))
        else:
            u = np.asarray(direction, float) / math.hypot(direction[0], direction[1])
            length = float(np.ptp(poly @ u))
        return self.footprint_fraction * length


RECOGNIZERS = ("cdvs", "vocab")


@dataclass(frozen=True)
class VocabLoopConfig(Config):
    """Loop detection with the vocabulary tree (loops.vocab), used when loops.recognizer is vocab."""

    vocabulary: str | None = setting(None, doc="vocabulary file (.voc); None = the floor vocabulary shipped with loops")
    n_features: int = setting(500, range="[1, inf)", doc="ORB keypoints per keyframe")
    min_shared_words: int = setting(5, range="[1, inf)",
                                    doc="a stored keyframe sharing fewer words with the query is not a candidate")
    ratio: float = setting(0.8, range="(0, 1]", doc="geometric check: descriptor ratio test of the keypoint matches")
    min_inliers: int = setting(20, range="[2, inf)", doc="accepted with at least this many matches on one floor motion")
    threshold_px: float = setting(6.0, range="(0, inf)", unit="px", doc="and within this many pixels of it")


@dataclass(frozen=True)
class LoopConfig(Config):
    """Loop detection (compact descriptors, loops.cdvs, or the vocabulary tree, loops.vocab) and the loop's
    relative pose on the floor."""

    enabled: bool = True
    recognizer: str = setting("cdvs", doc="place recogniser: cdvs or vocab (settings in vocab)")
    mode: int = setting(4, choices=MODES, doc="descriptor size mode 1..6 (512 B .. 16 kB per keyframe)")
    model: str | None = None         # P(loop|score) model JSON; None = the model shipped with the package
    floor_preset: bool = True        # similarity geometry for a downward camera (CdvsParams.floor)
    # recent keyframes are excluded by time and footprint (loops.loop_detector: a keyframe is a candidate once the
    # camera has left its footprint and it is exclude_seconds old), never by a count: a count of keyframes means
    # seconds at 30 fps and minutes at 0.14 Hz
    # gated_min_probability 0.5: below the P = 1 threshold, a verified candidate more likely a loop than not by its
    # score alone is accepted when the motion gate confirms it (slow revisits: the demo's closing keyframes score
    # 12-19, P 0.85-0.985); chosen on our simulator seeds 1-3 (0.5 against 0.9)
    database: DatabaseParams = field(default_factory=lambda: DatabaseParams(exclude_recent=0, exclude_seconds=2.0,
                                                                            min_overlap=0.2,
                                                                            gated_min_probability=0.5))
    exclude_distance: float | None = setting(None, range="[0, inf)", unit="m",
                                             doc="also exclude keyframes this far back along the path, as a count "
                                                 "of keyframes at the keyframe spacing (None: time and footprint "
                                                 "only; a count breaks at aerial scale)")
    pose_threshold_px: float = setting(3.0, range="(0, inf)", unit="px",
                                       doc="RANSAC threshold of the floor-plane fit of a loop's inlier pairs")
    min_pose_inliers: int = setting(12, range="[2, inf)",
                                    doc="fewer consistent pairs: the loop gives no pose and is not used")
    pose_pixel_sigma: float = setting(1.0, range="(0, inf)", unit="px",
                                      doc="pixel noise of decoded keypoints (coarse coordinate coding)")
    # a loop's fit covariance (sigma^2 (J^T J)^-1) treats its pairs as independent and shrinks as 1/inliers, but
    # each image's registration on the floor carries an error common to all its points (camera tilt and height at
    # that instant: ~2 mm at 0.5 m for a 0.2 deg wobble) that no number of pairs removes; the fit's RMS residual is
    # the per-image scale of that error (decoded-keypoint noise plus the tilt's perspective bend)
    image_sigma_rms: float = setting(1.0, range="[0, inf)", unit="fit RMS residuals",
                                     doc="per-axis position sigma of each of a loop's two images, added to the "
                                         "loop's covariance in the graph (0: the fit's covariance alone)")
    # loops accepted below the P = 1 threshold (database.gated_min_probability) fit 25-45 pairs on a small overlap:
    # on the tuning sequences (our simulator seeds 1-3 and render_floor s21/s22, 2 laps; the 100 m carpet loop)
    # their rotation error was 1.5-2x the fit's stated sigma (median |error|/sigma 1.0-1.3, 0.67 for a consistent
    # Gaussian) while loops above the threshold matched theirs (0.6-0.8); a rotation error is what a lap-long graph
    # turns into position error (0.01 deg is 3 mm at 16 m)
    gated_rotation_variance: float = setting(3.0, range="[1, inf)", unit="x the fit's rotation variance",
                                             doc="rotation variance in the graph of a loop accepted below the "
                                                 "score threshold (gated acceptance), relative to its fit's")
    vocab: VocabLoopConfig = field(default_factory=VocabLoopConfig)
    # a verified loop must agree with the visual odometry between its two keyframes (drift-aware; the loop's floor
    # fit above is the one judged, and the one given to the graph). The drift model is the generic one, not our VO's
    # measured drift on simulated floors (motion_gate.vo_drift, 0.2 x): nothing here measures the VO's drift on the
    # user's imagery, and a gate narrower than the real drift silently refuses true loops, where a wider one only
    # passes candidates on to the robust back end (docs/loops.md)
    gate: MotionGateParams = field(default_factory=MotionGateParams)

    def check(self) -> None:
        if self.recognizer == "horizon":
            raise ConfigError("loops.recognizer: horizon (1D SURF) recognises the skyline seen by a forward-looking "
                              "camera; the SLAM pipeline's camera looks down at the floor (camera_height), where "
                              "there is no horizon. Use cdvs or vocab (the horizon recogniser is for `vslam horizon`)")
        if self.recognizer not in RECOGNIZERS:
            raise ConfigError(f"loops.recognizer must be one of {', '.join(RECOGNIZERS)}, got {self.recognizer!r}")


@dataclass(frozen=True)
class RecordingConfig(Config):
    # Defaults keep recording.rrd at about 6 kB per frame on the demo (57 kB at full size, every frame, quality 70):
    # a 320x240 image is still readable beside the 3D scene, and at 20 frames/s every 3rd image still plays.
    enabled: bool = True
    image_every: int = setting(3, range="[1, inf)", unit="frames",
                               doc="log every n-th camera image, with its keypoints and matches (1 = all)")
    image_scale: float = setting(0.5, range="(0, 1]", unit="fraction of full resolution",
                                 doc="the logged image's size relative to the camera's")
    jpeg_quality: int = setting(60, range="[0, 100]", unit="JPEG quality", doc="of the logged image")


@dataclass(frozen=True)
class PipelineConfig(Config):
    vo: VOConfig = field(default_factory=VOConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    keyframes: KeyframePolicy = field(default_factory=KeyframePolicy)
    loops: LoopConfig = field(default_factory=LoopConfig)
    graph: GraphParams = field(default_factory=GraphParams)
    incremental: bool = False        # iSAM2 as keyframes arrive (else batch LM, re-run as loops arrive and at the end)
    optimize_every: int = setting(10, range="[0, inf)",
                                  doc="batch mode: re-optimise after this many new accepted loops (0: only at the end)")
    recording: RecordingConfig = field(default_factory=RecordingConfig)
    seed: int = setting(0, range="[0, inf)")

    def database_params(self, camera: CameraModel | None = None) -> DatabaseParams:
        """The loop database settings, with the recent-keyframe exclusion converted from metres to keyframes at the
        keyframe spacing for `camera` (without a camera, only a metric `keyframes.distance` converts)."""
        db = self.loops.database
        if self.loops.exclude_distance is None:
            return db
        if camera is None and self.keyframes.distance is None:
            return db
        spacing = self.keyframes.distance if camera is None else self.keyframes.spacing(camera)
        return db.replace(exclude_recent=int(math.ceil(self.loops.exclude_distance / spacing)))
