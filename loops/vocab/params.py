"""Tunables of visual-memory localisation, gathered in one dataclass with named presets.

Every knob the paper (Aldana-Murillo, Hayet, Becerra: visual bag of words for humanoid localisation) tunes lives
here: branch factor k and depth L of the vocabulary tree, the histogram distance, the minimum number of shared
words for a key image to be a candidate, the BRIEFROT angle, the BRIEF patch, and the colour patch layout.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

from odometry.shared.config import Config, ConfigError, setting


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
class VocabParams(Config):
    PRESETS = {
        # the paper's final choice (Sec. 4.3): k = 8, L = 8, chi-square, 500 features, theta = 8 degrees
        "paper": {"k": 8, "depth": 8},
        # our default: same method, a shallower tree that builds fast from a few hundred images
        "default": {},
        # tiny vocabularies for tests and quick looks
        "fast": {"k": 6, "depth": 3, "kmeans_iters": 5, "n_features": 200},
    }

    descriptor: DescriptorName = DescriptorName.BRIEF
    # vocabulary tree (Nister-Stewenius): branch factor k, depth L, Lloyd iterations per node, build seed
    k: int = setting(10, range="[2, inf)", doc="branch factor of the vocabulary tree")
    depth: int = setting(5, range="[1, inf)", doc="depth L of the vocabulary tree")
    kmeans_iters: int = setting(10, range="[1, inf)", doc="Lloyd iterations per node")
    kmeans_restarts: int = setting(1, range="[1, inf)")   # k-means++ runs per node, the lowest inertia kept
    #                                                       (3 measured no steadier)
    seed: int = setting(0, range="[0, inf)", doc="tree build seed")
    max_train_descriptors: int = setting(200_000, range="[2, inf)",
                                         doc="a seeded subsample trains the tree when the memory has more")
    # database and scoring
    distance: Distance = Distance.CHI2
    min_shared_words: int = setting(5, range="[1, inf)", doc="words a key image must share to be a candidate")
    # keypoint descriptors
    n_features: int = setting(500, range="[1, 100000]", doc="keypoints per image")
    min_image_side: int = setting(0, range="[0, 20000]", unit="px",
                                  doc="upscale smaller images so their shorter side reaches this (0 = never)")
    brief_patch: int = setting(48, range="[8, 1024]", unit="px", doc="BRIEF patch side (paper: 48)")
    brief_sigma: float = setting(2.0, range="[0, 100]", unit="px", doc="Gaussian smoothing before the BRIEF tests")
    brief_pattern_seed: int = setting(1234, range="[0, inf)")   # fixed: vocabularies built with one pattern only
    #                                                             work with that pattern
    rot_theta_deg: float = setting(8.0, range="[0, 180]", unit="deg",
                                   doc="BRIEFROT angle (paper: 8 degrees, found by the Fig. 9 sweep)")
    # colour descriptors: patches of patch_fraction x the image size; H-S histogram with hs_bins x hs_bins bins
    color_random_patches: int = setting(500, range="[1, 100000]")
    color_grid: int = setting(10, range="[1, 1000]",
                              doc="partitions per axis; half-overlapping patches -> (2g-1)^2 = 361")
    color_patch_fraction: float = setting(0.1, range="(0, 1]", doc="64x48 at 640x480, as in the paper")
    hs_bins: int = setting(8, range="[2, 32]", doc="8 x 8 = 64-dimensional descriptor")

    def check(self) -> None:
        if self.max_train_descriptors < self.k:
            raise ConfigError("max_train_descriptors must be >= k")


# The presets by name (VocabParams.PRESETS) and a preset with some fields overridden, e.g. preset("paper",
# descriptor="orb"): the names the package has always exported.
PRESETS = VocabParams.PRESETS
preset = VocabParams.preset
