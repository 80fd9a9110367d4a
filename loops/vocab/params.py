"""Tunables of visual-memory localisation, gathered in one dataclass with named presets.

Every knob the paper (Aldana-Murillo, Hayet, Becerra: visual bag of words for humanoid localisation) tunes lives
here: branch factor k and depth L of the vocabulary tree, the histogram distance, the minimum number of shared
words for a key image to be a candidate, the BRIEFROT angle, the BRIEF patch, and the colour patch layout.
"""
from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass

from odometry.shared.errors import ConfigError


class DescriptorName(str, enum.Enum):
    """The seven vocabularies of the paper (CLI names)."""

    BRIEF = "brief"                # FAST (ORB's oFAST detector) + BRIEF on a Gaussian-smoothed image, 256 bits
    BRIEFROT = "briefrot"          # three BRIEF vocabularies with the pattern at 0, +theta, -theta; score = max (eq. 2)
    ORB = "orb"                    # OpenCV ORB, 256 bits
    SURF = "surf"                  # SURF is not in our OpenCV build: SIFT (128 floats, L2) stands in for it
    COLOR_RANDOM = "color-random"  # H-S histograms of random patches
    COLOR_WHOLE = "color-whole"    # H-S histograms on a half-overlapping grid over the whole image
    COLOR_HALF = "color-half"      # the same grid over the upper half of the image only

    @property
    def is_binary(self) -> bool:
        return self in (DescriptorName.BRIEF, DescriptorName.BRIEFROT, DescriptorName.ORB)

    @property
    def is_color(self) -> bool:
        return self in (DescriptorName.COLOR_RANDOM, DescriptorName.COLOR_WHOLE, DescriptorName.COLOR_HALF)

    @property
    def label(self) -> str:
        """Name for tables, in the paper's spelling."""
        return {"brief": "BRIEF", "briefrot": "BRIEFROT", "orb": "ORB", "surf": "SURF (SIFT)",
                "color-random": "Color-Random", "color-whole": "Color-Whole", "color-half": "Color-Half"}[self.value]


class Distance(str, enum.Enum):
    """Histogram comparisons. Each is turned into a similarity score in [0, 1] (1 = identical histograms) that only
    needs the words two images share, so it is computed from the inverted index:

    chi2           1 - chi2/2 = 2 sum v w / (v + w)        (L1-normalised vectors; the paper's choice)
    dot            sum v w                                  (L2-normalised)
    bhattacharyya  sum sqrt(v w)                            (L1-normalised; the Bhattacharyya coefficient)
    l1             1 - |v - w|_1 / 2 = sum min(v, w)        (L1-normalised)
    l2             1 - |v - w|_2 / sqrt(2)                  (L2-normalised)
    """

    CHI2 = "chi2"
    DOT = "dot"
    BHATTACHARYYA = "bhattacharyya"
    L1 = "l1"
    L2 = "l2"

    @property
    def norm(self) -> str:
        return "l2" if self in (Distance.DOT, Distance.L2) else "l1"


@dataclass(frozen=True)
class VocabParams:
    descriptor: DescriptorName = DescriptorName.BRIEF
    # vocabulary tree (Nister-Stewenius): branch factor k, depth L, Lloyd iterations per node, build seed
    k: int = 10
    depth: int = 5
    kmeans_iters: int = 10
    kmeans_restarts: int = 1               # k-means++ runs per node, the lowest inertia kept (3 measured no steadier)
    seed: int = 0
    max_train_descriptors: int = 200_000   # a seeded subsample trains the tree when the memory has more
    # database and scoring
    distance: Distance = Distance.CHI2
    min_shared_words: int = 5
    # keypoint descriptors
    n_features: int = 500
    min_image_side: int = 0                # upscale smaller images so their shorter side reaches this (0 = never)
    brief_patch: int = 48                  # BRIEF patch side in pixels (paper: 48)
    brief_sigma: float = 2.0               # Gaussian smoothing before the BRIEF tests
    brief_pattern_seed: int = 1234         # fixed: vocabularies built with one pattern only work with that pattern
    rot_theta_deg: float = 8.0             # BRIEFROT angle (paper: 8 degrees, found by the Fig. 9 sweep)
    # colour descriptors: patches of patch_fraction x the image size; H-S histogram with hs_bins x hs_bins bins
    color_random_patches: int = 500
    color_grid: int = 10                   # partitions per axis; half-overlapping patches -> (2g-1)^2 = 361
    color_patch_fraction: float = 0.1      # 64x48 at 640x480, as in the paper
    hs_bins: int = 8                       # 8 x 8 = 64-dimensional descriptor

    def __post_init__(self) -> None:
        object.__setattr__(self, "descriptor", DescriptorName(self.descriptor))
        object.__setattr__(self, "distance", Distance(self.distance))
        checks = [(self.k >= 2, "k must be >= 2"), (self.depth >= 1, "depth must be >= 1"),
                  (self.kmeans_iters >= 1, "kmeans_iters must be >= 1"),
                  (self.kmeans_restarts >= 1, "kmeans_restarts must be >= 1"),
                  (self.min_shared_words >= 1, "min_shared_words must be >= 1"),
                  (self.n_features >= 1, "n_features must be >= 1"),
                  (self.brief_patch >= 8, "brief_patch must be >= 8"),
                  (0 < self.color_patch_fraction <= 1, "color_patch_fraction must be in (0, 1]"),
                  (self.color_grid >= 1 and self.color_random_patches >= 1, "colour patch counts must be >= 1"),
                  (2 <= self.hs_bins <= 32, "hs_bins must be in [2, 32]"),
                  (self.max_train_descriptors >= self.k, "max_train_descriptors must be >= k")]
        for ok, msg in checks:
            if not ok:
                raise ConfigError(f"VocabParams: {msg}")

    def replace(self, **changes) -> "VocabParams":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["descriptor"] = self.descriptor.value
        d["distance"] = self.distance.value
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "VocabParams":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(d) - known
        if unknown:
            raise ConfigError(f"VocabParams: unknown field(s) {sorted(unknown)}")
        return cls(**d)


PRESETS: dict[str, VocabParams] = {
    # the paper's final choice (Sec. 4.3): k = 8, L = 8, chi-square, 500 features, theta = 8 degrees
    "paper": VocabParams(k=8, depth=8),
    # our default: same method, a shallower tree that builds fast from a few hundred images
    "default": VocabParams(),
    # tiny vocabularies for tests and quick looks
    "fast": VocabParams(k=6, depth=3, kmeans_iters=5, n_features=200),
}


def preset(name: str, **overrides) -> VocabParams:
    """A named preset with some fields overridden, e.g. preset("paper", descriptor="orb")."""
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r} (choose from {', '.join(PRESETS)})")
    return PRESETS[name].replace(**overrides)
