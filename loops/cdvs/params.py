"""Tunables of the compact descriptor, gathered in one dataclass with per-mode presets (like the CDVS per-mode table).

Modes 1-6 have hard byte budgets of 512 B, 1 kB, 2 kB, 4 kB, 8 kB and 16 kB. A mode trades the number of local
features, the bits kept per local descriptor and the size of the global descriptor against the budget.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from loops.geometry import GeometryModel
from odometry.shared.errors import ConfigError

MODES = (1, 2, 3, 4, 5, 6)
BUDGETS = {1: 512, 2: 1024, 3: 2048, 4: 4096, 5: 8192, 6: 16384}


@dataclass(frozen=True)
class ExtractionParams:
    """How an image becomes keypoints and descriptors (shared by all modes; only budgets differ per mode)."""

    max_side: int = 640            # images are resized so that max(w, h) <= max_side (as the CDVS reference)
    n_detect: int = 1000           # ORB/FAST keypoints detected on the pyramid before selection
    n_levels: int = 8              # pyramid levels (8 x 1.3: scale changes up to ~6x between photographs)
    scale_factor: float = 1.3      # pyramid scale step
    fast_threshold: int = 12       # FAST intensity threshold (low: floors such as tiles are low-contrast)
    dense_threshold: int = 30      # used instead when the image has more than dense_corners FAST corners
    dense_corners: int = 5000      # (carpet-like textures: ORB would spend its time scoring 10k+ corners)
    centre_prior: bool = True      # relevance prefers the image centre (photographs); off for floors
    n_described: int = 600         # keypoints (by relevance) that get an ORB descriptor; feed the global descriptor


@dataclass(frozen=True)
class ModeParams:
    """Per-mode budget split."""

    mode: int
    budget: int                    # hard limit on the serialised size in bytes
    desc_bits: int                 # bits kept per local descriptor (trained priority order), multiple of 8
    max_local: int                 # upper bound on local features (also bounds matching time)
    global_clusters: int           # at most this many codebook clusters are sent in the global descriptor
    coord_block: int               # coordinate quantisation block in processed-image pixels


@dataclass(frozen=True)
class MatchParams:
    """Local matching, geometric check and decision."""

    ratio: float = 0.90            # Lowe ratio on Hamming distances (d1 <= ratio * d2)
    max_distance_frac: float = 0.30  # reject nearest neighbours farther than this fraction of the bits
    min_matches: int = 5           # below this, no geometric check (local score 0)
    max_geometry_matches: int = 64  # DISTRAT + RANSAC see at most this many best-weighted matches (cost ~ K^2)
    distrat_chi2: float = 29.5435  # chi-square(24 dof) 80th percentile: below it the LDR histogram looks like outliers
    ransac_iterations: int = 24    # "a few RANSAC iterations" after DISTRAT (deterministic, seeded)
    ransac_threshold_frac: float = 0.01  # inlier threshold as a fraction of the processed image diagonal (8 px)
    geometry: GeometryModel = GeometryModel.AFFINE
    min_inliers: int = 4           # fewer final inliers -> local score 0
    # plausible transforms only (random matches fit arbitrary ones): overall scale range and, for the affine model,
    # largest singular-value ratio; mirrored transforms are always rejected. Photographs: scale changes up to 6x.
    scale_range: tuple[float, float] = (1.0 / 6.0, 6.0)
    max_anisotropy: float = 4.0


@dataclass(frozen=True)
class CdvsParams:
    """Everything tunable about encoding and matching for one mode. Use `CdvsParams.for_mode(m)`."""

    mode: ModeParams
    extraction: ExtractionParams = ExtractionParams()
    matching: MatchParams = MatchParams()

    @staticmethod
    def for_mode(mode: int, **overrides) -> "CdvsParams":
        if mode not in MODE_PRESETS:
            raise ConfigError(f"mode must be one of {MODES}, got {mode!r}")
        p = CdvsParams(mode=MODE_PRESETS[mode])
        return replace(p, **overrides) if overrides else p

    @staticmethod
    def floor(mode: int) -> "CdvsParams":
        """Preset for a downward camera over a planar floor: the image motion is a rotation + translation at a
        constant scale (the camera height does not change), so the similarity check only accepts scales near 1."""
        p = CdvsParams.for_mode(mode)
        return replace(p, mode=replace(p.mode, global_clusters=FLOOR_GLOBAL_CLUSTERS[mode]),
                       extraction=replace(p.extraction, centre_prior=False),
                       matching=replace(p.matching, geometry=GeometryModel.SIMILARITY, scale_range=(0.8, 1.25),
                                        ransac_threshold_frac=0.02))


# The per-mode table. Like the CDVS reference, the budget goes to many features with short descriptors rather than
# few long ones: on real photographs 96 bits x 300 features (mode 4) matched clearly more pairs than 160 x 180 or
# 256 x 115 (README, "48 real pairs"). max_local also bounds the matching time (all-pairs Hamming is N^2): modes 5
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
