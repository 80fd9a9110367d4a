"""Tunables of 1D SURF horizon landmarks, gathered in one frozen dataclass with named presets.

Defaults follow Anderson et al., "Robot Localisation Using Natural Landmarks" (1D SURF): a 30-pixel band summed
vertically and sampled every 4 pixels, 4 octaves x 3 intervals of box filters, nearest-neighbour ratio 0.7.
The paper leaves the response threshold, descriptor support, RANSAC settings and recognition threshold
unstated; ours are documented next to each field and were checked on the KITTI bank of `vslam bench horizon`
(neighbouring values change its AUC by less than 0.01).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

from odometry.shared.config import Config, setting


class SampleMode(str, enum.Enum):
    """How the band is reduced to one value every `step` columns."""

    COLUMN = "column"  # the paper: the band's sum in one column every `step` columns
    BOX = "box"        # the band's sum over all `step` columns of each sample (anti-aliased: a horizon that
                       # shifts by a non-multiple of `step` gives a signal closer to the unshifted one)


class Consensus(str, enum.Enum):
    """How the NN matches of two horizons are checked for geometric agreement (score_ransac)."""

    RANSAC = "ransac"  # the paper: RANSAC line x_test = b_s * x_stored + b_d
    SHIFT = "shift"    # not in the paper: the heaviest window of 2 * ransac_tolerance px in the shift x_test -
                       # x_stored (a turn; b_s = 1). One histogram per band instead of a hypothesis x match matrix,
                       # which is what makes loops.horizon.packed cheap enough to batch over many pairs


@dataclass(frozen=True)
class HorizonParams(Config):
    LABEL = "horizon"
    PRESETS = {
        # The paper's method with our choices for what it leaves unstated.
        "paper": {},
        # Two checks the paper does not make: one test feature per stored feature, and inliers whose feature-scale
        # ratio agrees with the fitted b_s. A little more discriminative (see `vslam bench horizon`).
        "robust": {"one_to_one": True, "scale_tolerance": 0.75},
        # Small real frames (e.g. 160x120): every column sampled, seven 12-row bands matched band by band
        # (loops.horizon.bands). Chosen on the tuning half of the real pairs of `vslam bench horizon --real`.
        "bands": {"step": 1, "band_height": 12, "bands": 7},
        # The batched path (loops.horizon.packed): seven 12-row bands sampled every 2 columns, 2 box filters per
        # octave (lobes 3, 5, 9, 17: fewer candidates), the 16 strongest features per band, shift consensus in a 16-px window of at least 2 matches. Chosen on the tuning half of
        # `vslam bench horizon --real-only` as the cheapest setting whose AUC stays well above full-image ORB's
        # there; the pixel values suit frames of about 120-400 rows, like `bands`. Its scores sum seven bands, so
        # its recognition threshold is its own: 220 keeps false positives <= 5 % on that tuning half (4.4 %, 55 %
        # of matched pairs accepted; reporting half 5.9 % / 53.6 %). The memory, the recogniser and `vslam horizon`
        # (whose default preset this is) score it through loops.horizon.packed.
        "fast": {"step": 2, "band_height": 12, "bands": 7, "intervals": 2, "max_features": 16, "consensus": "shift",
                 "ransac_tolerance": 16.0, "ransac_min_inliers": 2, "recognition_threshold": 220.0},
        # The packed path at its lightest for a lone pair (two extractions and one match, where the per-call cost
        # of the array operations is most of the time): three 16-row bands sampled every 4 columns, the 8 strongest
        # features per band, otherwise as `fast`. Chosen on the tuning half of `vslam bench horizon --real-only`
        # (grid: 3-7 bands of 12 or 16 rows, 8-16 features, step 2 or 4; 1-2 bands checked after) as the fewest
        # bands x features whose AUC is at least 0.04 above ORB(1000) + RANSAC's there (0.804 against 0.762; the
        # margin is ORB's tuning-to-reporting drop, 0.029, plus fast's, 0.015). Threshold 36: <= 5 % false
        # positives on that tuning half (4.8 %, 45 % of matched pairs accepted; reporting half 9.9 % / 46 %).
        "lone": {"step": 4, "band_height": 16, "bands": 3, "intervals": 2, "max_features": 8, "consensus": "shift",
                 "ransac_tolerance": 16.0, "ransac_min_inliers": 2, "recognition_threshold": 36.0},
        # A lone pair on the compiled kernels (loops.horizon.packed_jit, numba), where the cost is arithmetic, not
        # array calls: five 12-row bands sampled every 4 columns, the 12 strongest features per band, otherwise as
        # `fast`. Chosen on the tuning half of `vslam bench horizon --real-only` (grid: 3, 5, 7 bands of 12 or 16
        # rows, 8, 12, 16 features, step 2 or 4, all compiled, ORB in the same run) as the highest AUC whose lone
        # pair (two extractions and one match) costs at most 1/60 of ORB(1000) + RANSAC's (1/50 with a 20 %
        # margin for run-to-run timing): 0.855 at 1/64, against `lone`'s 0.804 and ORB's 0.762. Threshold 88:
        # <= 5 % false positives on that tuning half (4.8 %, 51 % of matched pairs accepted; reporting half 5.9 %
        # / 48 %). Without numba it runs the numpy code, at numpy's cost.
        "lone_compiled": {"step": 4, "band_height": 12, "bands": 5, "intervals": 2, "max_features": 12,
                          "consensus": "shift", "ransac_tolerance": 16.0, "ransac_min_inliers": 2,
                          "recognition_threshold": 88.0},
    }

    # --- horizon signal (paper §3) ---
    band_height: int = setting(30, range="[1, inf)", unit="px",
                               doc="rows summed at each sample; centred on the horizon row")
    step: int = setting(4, range="[1, inf)", unit="px", doc="image columns between samples")
    sample_mode: SampleMode = SampleMode.COLUMN
    bands: int = setting(1, range="[1, inf)",
                         doc="bands of band_height rows stacked around the horizon row, matched band by band "
                             "by loops.horizon.bands (extract_bands / match_bands) and loops.horizon.packed; the "
                             "landmark memory, the recogniser and `vslam horizon` read every band on the packed "
                             "path (preset fast), the horizon row's band only otherwise")

    # --- detector (paper §3) ---
    octaves: int = setting(4, range="[1, inf)")
    intervals: int = setting(3, range="[1, inf)",
                             doc="box filters per octave; lobe = 2^(o+1) * (i+1) + 1 samples, as in SURF")
    threshold: float = setting(1.0, range="[0, inf)",
                               doc="on |scale-normalised second derivative|, grey levels per band pixel")
    max_features: int = setting(0, range="[0, inf)", unit="features per band",
                                doc="keep the strongest (largest |response|) features of each band; 0 keeps all. "
                                    "Bounds the matching cost, which grows with the square of the count")

    # --- descriptor: 3 subregions of Haar responses, (sum dx, sum |dx|) each -> 6 numbers, unit length ---
    subregions: int = setting(3, range="[1, inf)")
    samples_per_subregion: int = setting(5, range="[1, inf)",
                                         doc="SURF's 5 samples per subregion, spaced by the feature scale s")
    descriptor_window: float = setting(15.0, range="(0, inf)",
                                       doc="total support in units of s (SURF: 20 s over 4 subregions)")
    gaussian_sigma: float = setting(3.3, range="(0, inf)",
                                    doc="Gaussian weighting of the Haar samples, in units of s (as SURF)")

    # --- matching (paper §3.1) ---
    ratio: float = setting(0.7, range="(0, 1]", doc="nearest / second-nearest descriptor distance")
    match_sign: bool = True        # only bright blobs match bright blobs (SURF's sign-of-Laplacian test)
    one_to_one: bool = False       # a stored feature keeps only its closest test feature (not in the paper)
    min_distance: float = setting(0.05, range="(0, inf)",
                                  doc="floor on the distance in the 1/d score so a perfect match cannot dominate")
    ransac_iterations: int = setting(100, range="[1, inf)", doc="hypotheses; all pairs are tried when there are fewer")
    ransac_tolerance: float = setting(8.0, range="(0, inf)", unit="px",
                                      doc="inlier residual of x_test = b_s * x_stored + b_d")
    ransac_min_inliers: int = setting(3, range="[2, inf)",
                                      doc="fewer consistent matches give score_ransac = 0 (two points fit any line)")
    max_scale_change: float = setting(2.0, range="[1, inf)",
                                      doc="b_s must lie in [1/max, max]; b_s <= 0 would reverse the horizon order")
    consensus: Consensus = setting(Consensus.RANSAC,
                                   doc="geometric check of score_ransac: 'ransac' (the paper's line) or 'shift' (the "
                                       "heaviest 2 x ransac_tolerance window of x_test - x_stored; needed by "
                                       "loops.horizon.packed)")
    scale_tolerance: float = setting(0.0, range="[0, inf)")   # > 0: inliers' feature-scale ratio must agree with
    #                                                           b_s within this many octaves (not in the paper; 0
    #                                                           disables)
    seed: int = setting(0, range="[0, inf)",
                        doc="RANSAC sampling seed (results are deterministic for a given seed)")

    # --- recognition (paper §4: a threshold on the NN+RANSAC score; theirs was 100 in their units) ---
    recognition_threshold: float = setting(70.0, range="[0, inf)", unit="score (sum of 1 / descriptor distance)",
                                           doc="~5% false positives on the KITTI bank (`vslam bench horizon`); "
                                               "preset fast: 220 (its scores sum seven bands); lone: 36; "
                                               "lone_compiled: 88")


# The presets by name: the name the package has always exported.
PRESETS = HorizonParams.PRESETS
