"""Tunables of the compact descriptor, gathered in one dataclass with per-mode presets (like the CDVS per-mode table).

Modes 1-6 have hard byte budgets of 512 B, 1 kB, 2 kB, 4 kB, 8 kB and 16 kB. A mode trades the number of local
features, the bits kept per local descriptor and the size of the global descriptor against the budget.
"""
from __future__ import annotations

from dataclasses import dataclass

from loops.geometry import GeometryModel
from odometry.shared.config import Config, ConfigError, setting

MODES = (1, 2, 3, 4, 5, 6)
BUDGETS = {1: 512, 2: 1024, 3: 2048, 4: 4096, 5: 8192, 6: 16384}


@dataclass(frozen=True)
class ExtractionParams(Config):
    """How an image becomes keypoints and descriptors (shared by all modes; only budgets differ per mode)."""

    max_side: int = setting(640, range="[1, inf)", unit="px",
                            doc="images are resized so that max(w, h) <= max_side (as the CDVS reference)")
    n_detect: int = setting(1000, range="[1, inf)", doc="ORB/FAST keypoints detected on the pyramid before selection")
    n_levels: int = setting(8, range="[1, inf)",
                            doc="pyramid levels (8 x 1.3: scale changes up to ~6x between photographs)")
    scale_factor: float = setting(1.3, range="(1, inf)", doc="pyramid scale step")
    fast_threshold: int = setting(12, range="[0, 255]",
                                  doc="FAST intensity threshold (low: floors such as tiles are low-contrast)")
    dense_threshold: int = setting(30, range="[0, 255]",
                                   doc="used instead when the image has more than dense_corners FAST corners")
    dense_corners: int = setting(5000, range="[0, inf)",
                                 doc="(carpet-like textures: ORB would spend its time scoring 10k+ corners)")
    centre_prior: bool = True      # relevance prefers the image centre (photographs); off for floors
    n_described: int = setting(600, range="[1, inf)",
                               doc="keypoints (by relevance) that get an ORB descriptor; feed the global descriptor")


@dataclass(frozen=True)
class ModeParams(Config):
    """Per-mode budget split."""

    mode: int = setting(choices=MODES)
    budget: int = setting(range="[1, inf)", unit="bytes", doc="hard limit on the serialised size")
    desc_bits: int = setting(range="[8, 256]",
                             doc="bits kept per local descriptor (trained priority order), multiple of 8")
    max_local: int = setting(range="[1, inf)", doc="upper bound on local features (also bounds matching time)")
    global_clusters: int = setting(range="[1, inf)",
                                   doc="at most this many codebook clusters are sent in the global descriptor")
    coord_block: int = setting(range="[1, inf)", unit="px",
                               doc="coordinate quantisation block in processed-image pixels")

    def check(self) -> None:
        if self.desc_bits % 8:
            raise ConfigError(f"desc_bits must be a multiple of 8, got {self.desc_bits}")


@dataclass(frozen=True)
class MatchParams(Config):
    """Local matching, geometric check and decision."""

    ratio: float = setting(0.90, range="(0, 1]", doc="Lowe ratio on Hamming distances (d1 <= ratio * d2)")
    max_distance_frac: float = setting(0.30, range="(0, 1]",
                                       doc="reject nearest neighbours farther than this fraction of the bits")
    min_matches: int = setting(5, range="[0, inf)", doc="below this, no geometric check (local score 0)")
    max_geometry_matches: int = setting(64, range="[1, inf)",
                                        doc="DISTRAT + RANSAC see at most this many best-weighted matches (cost ~ K^2)")
    distrat_chi2: float = setting(29.5435, range="[0, inf)",
                                  doc="chi-square(24 dof) 80th percentile: below it the LDR histogram looks like "
                                      "outliers")
    ransac_iterations: int = setting(24, range="[1, inf)",
                                     doc='"a few RANSAC iterations" after DISTRAT (deterministic, seeded)')
    ransac_threshold_frac: float = setting(0.01, range="(0, inf)",
                                           doc="inlier threshold as a fraction of the processed image diagonal (8 px)")
    geometry: GeometryModel = GeometryModel.AFFINE
    min_inliers: int = setting(4, range="[0, inf)", doc="fewer final inliers -> local score 0")
    # plausible transforms only (random matches fit arbitrary ones): overall scale range and, for the affine model,
    # largest singular-value ratio; mirrored transforms are always rejected. Photographs: scale changes up to 6x.
    scale_range: tuple[float, float] = setting((1.0 / 6.0, 6.0), range="(0, inf)")
    max_anisotropy: float = setting(4.0, range="[1, inf)")

    def check(self) -> None:
        if self.scale_range[0] > self.scale_range[1]:
            raise ConfigError(f"scale_range must be (low, high) with low <= high, got {list(self.scale_range)}")


@dataclass(frozen=True)
class CdvsParams(Config):
    """Everything tunable about encoding and matching for one mode. Build it with `CdvsParams.for_mode(m)` (the
    per-mode table) or `CdvsParams.floor(m)` (the same for a downward camera over a planar floor)."""

    mode: ModeParams
    extraction: ExtractionParams = ExtractionParams()
    matching: MatchParams = MatchParams()

    @staticmethod
    def for_mode(mode: int, **overrides) -> "CdvsParams":
        if mode not in MODE_PRESETS:
            raise ConfigError(f"mode must be one of {MODES}, got {mode!r}")
        p = CdvsParams(mode=MODE_PRESETS[mode])
        return p.replace(**overrides) if overrides else p

    @staticmethod
    def floor(mode: int) -> "CdvsParams":
        """Preset for a downward camera over a planar floor: the image motion is a rotation + translation at a
        constant scale (the camera height does not change), so the similarity check only accepts scales near 1."""
        return CdvsParams.for_mode(mode).replace(
            mode={"global_clusters": FLOOR_GLOBAL_CLUSTERS[mode]}, extraction={"centre_prior": False},
            matching={"geometry": GeometryModel.SIMILARITY, "scale_range": (0.8, 1.25), "ransac_threshold_frac": 0.02})


# The per-mode table. Like the CDVS reference, the budget goes to many features with short descriptors rather than
# few long ones: on real photographs 96 bits x 300 features (mode 4) matched clearly more pairs than 160 x 180 or
# 256 x 115 (docs/benchmarks.md, "48 real pairs"). max_local also bounds the matching time (all-pairs Hamming is N^2): modes 5
# and 6 do not fill their budgets. The global descriptor sends the 20 most populated clusters (their residual signs
# are the stable ones); the floor preset keeps more (modes 4-6: all 64 words) for the database shortlist (FLOOR_GLOBAL_CLUSTERS).
# The encoder enforces the budget exactly, dropping the least relevant features when coordinates cost more.
MODE_PRESETS: dict[int, ModeParams] = {
    1: ModeParams(1, BUDGETS[1], desc_bits=48, max_local=80, global_clusters=20, coord_block=3),
    2: ModeParams(2, BUDGETS[2], desc_bits=64, max_local=120, global_clusters=20, coord_block=3),
    3: ModeParams(3, BUDGETS[3], desc_bits=80, max_local=200, global_clusters=20, coord_block=3),
    4: ModeParams(4, BUDGETS[4], desc_bits=96, max_local=300, global_clusters=20, coord_block=2),
    5: ModeParams(5, BUDGETS[5], desc_bits=128, max_local=300, global_clusters=20, coord_block=2),
    6: ModeParams(6, BUDGETS[6], desc_bits=192, max_local=300, global_clusters=20, coord_block=2),
}
FLOOR_GLOBAL_CLUSTERS = {1: 20, 2: 40, 3: 64, 4: 128, 5: 128, 6: 128}
