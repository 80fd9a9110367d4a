"""Several bands around the horizon (not in the paper): 1D SURF in each, matched band by band, scores summed.

One band of a real image holds few 1D features (a 160-px corridor frame gives about 30 at the paper's 4-px
sampling), so a single band's score is noisy. Bands stacked above and below the horizon row see different parts of
the same scene (floor edges, doors, ceiling lights); a place seen again matches in most of them, a different place
in few. Each band is matched with its counterpart only (the camera stays level: the scene does not move between
bands), and the NN+RANSAC scores add up.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loops.horizon.matching import MatchResult, match
from loops.horizon.params import HorizonParams
from loops.horizon.surf1d import HorizonFeatures, extract_features


@dataclass(frozen=True)
class BandsMatch:
    score: float               # sum of the bands' NN scores
    score_ransac: float        # sum of the bands' NN+RANSAC scores
    per_band: tuple[MatchResult, ...]


def band_rows(row: float, height: int, params: HorizonParams) -> list[float]:
    """The centre rows of `params.bands` bands, `band_height` apart and centred on `row`, moved inside an image of
    `height` rows when they would leave it."""
    half = params.band_height / 2.0
    lo, hi = half, height - half
    if hi < lo:
        return [height / 2.0]
    offsets = (np.arange(params.bands) - (params.bands - 1) / 2.0) * params.band_height
    return [float(np.clip(row + o, lo, hi)) for o in offsets]


def extract_bands(image: np.ndarray, row: float, params: HorizonParams = HorizonParams()) -> list[HorizonFeatures]:
    """1D SURF features of each band (params.bands of them) around the horizon `row`."""
    return [extract_features(image, r, params) for r in band_rows(row, image.shape[0], params)]


def match_bands(test: list[HorizonFeatures], stored: list[HorizonFeatures],
                params: HorizonParams = HorizonParams()) -> BandsMatch:
    """Match band k of `test` with band k of `stored`; scores summed over the bands."""
    if len(test) != len(stored):
        raise ValueError(f"{len(test)} bands against {len(stored)}")
    per = tuple(match(t, s, params) for t, s in zip(test, stored))
    return BandsMatch(float(sum(m.score for m in per)), float(sum(m.score_ransac for m in per)), per)
