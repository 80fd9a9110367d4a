"""`PipelineConfig`: every tunable of a SLAM run in one place, with sane defaults, loadable from YAML or TOML.

Sections reuse each package's own parameter classes (VOConfig, FusionConfig, DatabaseParams, GraphParams), so a
config file can set anything those expose:

    vo:        {max_features: 300}
    loops:     {mode: 5, database: {confirmations: 2}}      # or {recognizer: vocab, vocab: {min_inliers: 25}}
    graph:     {robust: gnc}
    keyframes: {distance: 0.1}
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from graph.params import GraphParams
from loops.cdvs.params import MODES
from loops.loop_detector import DatabaseParams
from odometry.fusion import FusionConfig
from odometry.vo import VOConfig
from vslam.pipeline.dataclass_io import ConfigError, from_dict, to_dict


@dataclass(frozen=True)
class KeyframePolicy:
    """When a frame becomes a loop keyframe (and a pose-graph node): after the robot moved or turned enough."""

    # 0.25 m is well inside the 0.64 x 0.48 m footprint of the default camera: a revisit always finds a stored
    # keyframe within 0.125 m along the track, so J >= 0.33 loops are not missed for lack of keyframes
    distance: float = 0.25           # metres travelled since the last keyframe
    angle_deg: float = 20.0          # or degrees turned
    max_frames: int = 60             # or frames elapsed (keeps the graph connected when standing still)

    def __post_init__(self) -> None:
        if self.distance <= 0 or self.angle_deg <= 0 or self.max_frames < 1:
            raise ConfigError("keyframes.distance, angle_deg and max_frames must be positive")


RECOGNIZERS = ("cdvs", "vocab")


@dataclass(frozen=True)
class VocabLoopConfig:
    """Loop detection with the vocabulary tree (loops.vocab), used when loops.recognizer is vocab."""

    vocabulary: str | None = None    # vocabulary file (.voc); None = the floor vocabulary shipped with loops
    n_features: int = 500            # ORB keypoints per keyframe
    min_shared_words: int = 5        # a stored keyframe sharing fewer words with the query is not a candidate
    ratio: float = 0.8               # geometric check: descriptor ratio test of the keypoint matches
    min_inliers: int = 20            # accepted with at least this many matches on one floor motion
    threshold_px: float = 6.0        # and within this many pixels of it

    def __post_init__(self) -> None:
        if self.n_features < 1 or self.min_shared_words < 1 or self.min_inliers < 2:
            raise ConfigError("loops.vocab: n_features and min_shared_words must be >= 1, min_inliers >= 2")
        if not 0 < self.ratio <= 1 or self.threshold_px <= 0:
            raise ConfigError("loops.vocab: ratio must be in (0, 1] and threshold_px > 0")


@dataclass(frozen=True)
class LoopConfig:
    """Loop detection (compact descriptors, loops.cdvs, or the vocabulary tree, loops.vocab) and the loop's
    relative pose on the floor."""

    enabled: bool = True
    recognizer: str = "cdvs"         # "cdvs" or "vocab" (settings in the vocab section)
    mode: int = 4                    # descriptor size mode 1..6 (512 B .. 16 kB per keyframe)
    model: str | None = None         # P(loop|score) model JSON; None = the model shipped with the package
    floor_preset: bool = True        # similarity geometry for a downward camera (CdvsParams.floor)
    database: DatabaseParams = field(default_factory=DatabaseParams)
    # keyframes this far back along the path (metres) are not loop candidates; sets database.exclude_recent from
    # the keyframe spacing (None: use database.exclude_recent as given)
    exclude_distance: float | None = 2.0
    pose_threshold_px: float = 3.0   # RANSAC threshold of the floor-plane fit of a loop's inlier pairs
    min_pose_inliers: int = 12       # fewer consistent pairs: the loop gives no pose and is not used
    pose_pixel_sigma: float = 1.0    # pixel noise of decoded keypoints (coarse coordinate coding)
    vocab: VocabLoopConfig = field(default_factory=VocabLoopConfig)

    def __post_init__(self) -> None:
        if self.recognizer == "horizon":
            raise ConfigError("loops.recognizer: horizon (1D SURF) recognises the skyline seen by a forward-looking "
                              "camera; the SLAM pipeline's camera looks down at the floor (camera_height), where "
                              "there is no horizon. Use cdvs or vocab (the horizon recogniser is for `vslam horizon`)")
        if self.recognizer not in RECOGNIZERS:
            raise ConfigError(f"loops.recognizer must be one of {', '.join(RECOGNIZERS)}, got {self.recognizer!r}")
        if self.mode not in MODES:
            raise ConfigError(f"loops.mode must be one of {list(MODES)}, got {self.mode!r}")
        if self.exclude_distance is not None and self.exclude_distance < 0:
            raise ConfigError("loops.exclude_distance must be >= 0 metres")


@dataclass(frozen=True)
class RecordingConfig:
    enabled: bool = True
    image_every: int = 1             # log every n-th camera image (1 = all)
    jpeg_quality: int = 70


@dataclass(frozen=True)
class PipelineConfig:
    vo: VOConfig = field(default_factory=VOConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    keyframes: KeyframePolicy = field(default_factory=KeyframePolicy)
    loops: LoopConfig = field(default_factory=LoopConfig)
    graph: GraphParams = field(default_factory=GraphParams)
    incremental: bool = False        # iSAM2 as keyframes arrive (else batch LM, re-run as loops arrive and at the end)
    optimize_every: int = 10         # batch mode: re-optimise after this many new accepted loops (0: only at the end)
    recording: RecordingConfig = field(default_factory=RecordingConfig)
    seed: int = 0

    # ------------------------------------------------------------------ (de)serialisation
    def to_dict(self) -> dict:
        return to_dict(self)

    @classmethod
    def from_dict(cls, d: dict, where: str = "") -> "PipelineConfig":
        return from_dict(cls, d, where)

    @classmethod
    def load(cls, path: str | Path) -> "PipelineConfig":
        """Read a YAML (.yaml/.yml) or TOML (.toml) config; errors name the file and the setting."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: config file not found")
        text = path.read_text(encoding="utf-8")
        try:
            if path.suffix.lower() == ".toml":
                try:
                    import tomllib
                except ModuleNotFoundError:   # Python 3.10
                    import tomli as tomllib

                data = tomllib.loads(text)
            else:
                data = yaml.safe_load(text)
        except Exception as exc:  # yaml.YAMLError / tomllib.TOMLDecodeError
            raise ConfigError(f"{path}: cannot parse ({exc})") from None
        if data is None:
            data = {}
        try:
            return cls.from_dict(data)
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None

    def database_params(self) -> DatabaseParams:
        """The loop database settings, with the recent-keyframe exclusion converted from metres to keyframes."""
        db = self.loops.database
        if self.loops.exclude_distance is None:
            return db
        return dataclasses.replace(db, exclude_recent=int(math.ceil(self.loops.exclude_distance / self.keyframes.distance)))

    def dumps(self) -> str:
        return yaml.safe_dump(json.loads(json.dumps(self.to_dict())), sort_keys=False)
