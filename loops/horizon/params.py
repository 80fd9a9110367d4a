"""Tunables of 1D SURF horizon landmarks, gathered in one frozen dataclass with named presets.

Defaults follow Anderson et al., "Robot Localisation Using Natural Landmarks" (1D SURF): a 30-pixel band summed
vertically and sampled every 4 pixels, 4 octaves x 3 intervals of box filters, nearest-neighbour ratio 0.7.
The paper leaves the response threshold, descriptor support, RANSAC settings and recognition threshold
unstated; ours are documented next to each field and were checked on the KITTI bank of `vslam bench horizon`
(neighbouring values change its AUC by less than 0.01).
"""
from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass

from odometry.shared.errors import ConfigError


class SampleMode(str, enum.Enum):
    """How the band is reduced to one value every `step` columns."""

    COLUMN = "column"  # the paper: the band's sum in one column every `step` columns
    BOX = "box"        # the band's sum over all `step` columns of each sample (anti-aliased: a horizon that
                       # shifts by a non-multiple of `step` gives a signal closer to the unshifted one)


@dataclass(frozen=True)
class HorizonParams:
    # --- horizon signal (paper §3) ---
    band_height: int = 30          # rows summed at each sample; centred on the horizon row
    step: int = 4                  # image columns between samples
    sample_mode: SampleMode = SampleMode.COLUMN

    # --- detector (paper §3) ---
    octaves: int = 4
    intervals: int = 3             # box filters per octave; lobe = 2^(o+1) * (i+1) + 1 samples, as in SURF
    threshold: float = 1.0         # on |scale-normalised second derivative|, grey levels per band pixel

    # --- descriptor: 3 subregions of Haar responses, (sum dx, sum |dx|) each -> 6 numbers, unit length ---
    subregions: int = 3
    samples_per_subregion: int = 5  # SURF's 5 samples per subregion, spaced by the feature scale s
    descriptor_window: float = 15.0  # total support in units of s (SURF: 20 s over 4 subregions)
    gaussian_sigma: float = 3.3     # Gaussian weighting of the Haar samples, in units of s (as SURF)

    # --- matching (paper §3.1) ---
    ratio: float = 0.7             # nearest / second-nearest descriptor distance
    match_sign: bool = True        # only bright blobs match bright blobs (SURF's sign-of-Laplacian test)
    one_to_one: bool = False       # a stored feature keeps only its closest test feature (not in the paper)
    min_distance: float = 0.05     # floor on the distance in the 1/d score so a perfect match cannot dominate
    ransac_iterations: int = 100   # hypotheses; all pairs are tried when there are fewer
    ransac_tolerance: float = 8.0  # inlier residual of x_test = b_s * x_stored + b_d, in image pixels
    ransac_min_inliers: int = 3    # fewer consistent matches give score_ransac = 0 (two points fit any line)
    max_scale_change: float = 2.0  # b_s must lie in [1/max, max]; b_s <= 0 would reverse the horizon order
    scale_tolerance: float = 0.0   # > 0: inliers' feature-scale ratio must agree with b_s within this many octaves
                                   # (not in the paper; 0 disables)
    seed: int = 0                  # RANSAC sampling seed (results are deterministic for a given seed)

    # --- recognition (paper §4: a threshold on the NN+RANSAC score; theirs was 100 in their units) ---
    recognition_threshold: float = 70.0  # ~5% false positives on the KITTI bank (`vslam bench horizon`)

    def __post_init__(self) -> None:
        positive_ints = ("band_height", "step", "octaves", "intervals", "subregions", "samples_per_subregion",
                         "ransac_iterations")
        for name in positive_ints:
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ConfigError(f"HorizonParams.{name} must be a positive integer, got {v!r}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ConfigError(f"HorizonParams.seed must be a non-negative integer, got {self.seed!r}")
        if not self.scale_tolerance >= 0:
            raise ConfigError(f"HorizonParams.scale_tolerance must be >= 0, got {self.scale_tolerance!r}")
        for name in ("descriptor_window", "gaussian_sigma", "min_distance", "ransac_tolerance"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"HorizonParams.{name} must be > 0, got {getattr(self, name)!r}")
        object.__setattr__(self, "sample_mode", SampleMode(self.sample_mode))
        if not self.threshold >= 0:
            raise ConfigError(f"HorizonParams.threshold must be >= 0, got {self.threshold!r}")
        if not 0 < self.ratio <= 1:
            raise ConfigError(f"HorizonParams.ratio must be in (0, 1], got {self.ratio!r}")
        if not self.max_scale_change >= 1:
            raise ConfigError(f"HorizonParams.max_scale_change must be >= 1, got {self.max_scale_change!r}")
        if self.ransac_min_inliers < 2:
            raise ConfigError(f"HorizonParams.ransac_min_inliers must be >= 2, got {self.ransac_min_inliers!r}")

    def replace(self, **changes) -> "HorizonParams":
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["sample_mode"] = self.sample_mode.value
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "HorizonParams":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"unknown HorizonParams field(s): {', '.join(unknown)}")
        return cls(**d)

    @classmethod
    def preset(cls, name: str) -> "HorizonParams":
        try:
            return PRESETS[name]
        except KeyError:
            raise ConfigError(f"unknown horizon preset {name!r}; choose from {', '.join(PRESETS)}") from None


PRESETS: dict[str, HorizonParams] = {
    # The paper's method with our choices for what it leaves unstated.
    "paper": HorizonParams(),
    # Two checks the paper does not make: one test feature per stored feature, and inliers whose feature-scale
    # ratio agrees with the fitted b_s. A little more discriminative (see `vslam bench horizon`).
    "robust": HorizonParams(one_to_one=True, scale_tolerance=0.75),
}
