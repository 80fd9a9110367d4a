"""One home for scoring stored horizons against a test horizon, whichever path the parameters select.

- the per-pair path (loops.horizon.matching): one band at the horizon row, NN + RANSAC line (or shift) per pair;
- the packed path (loops.horizon.packed) when `uses_packed(params)` (preset `fast`): every band of a view in one
  pass, one test view against all stored views in one call.

The landmark memory, the recogniser, the verifier and the pair files of `vslam horizon` extract and score through
these functions only, so both paths give the same scores wherever they are used.
"""
from __future__ import annotations

from typing import Sequence, Union

import numpy as np

from loops.errors import LoopsError
from loops.horizon.matching import MatchResult, match
from loops.horizon.packed import (
    PackedBands,
    PackedMatch,
    PackedSet,
    extract_packed,
    match_packed,
    stack_packed,
    uses_packed,
)
from loops.horizon.params import HorizonParams
from loops.horizon.signal import HorizonLine
from loops.horizon.surf1d import HorizonFeatures, extract_features

HorizonView = Union[HorizonFeatures, PackedBands]      # what is stored and compared per image
HorizonMatch = Union[MatchResult, PackedMatch]          # .score, .score_ransac, .b_s, .b_d, .n_inliers


def extract_view(image: np.ndarray, horizon: float | HorizonLine, params: HorizonParams) -> HorizonView:
    """The horizon view of an image for `params`: PackedBands on the packed path, else HorizonFeatures."""
    if uses_packed(params):
        return extract_packed(image, horizon, params)
    return extract_features(image, horizon, params)


def check_view(view: HorizonView, params: HorizonParams, what: str) -> None:
    """LoopsError naming `what` when `view` was not extracted with parameters like `params`."""
    dim = 2 * params.subregions
    if uses_packed(params):
        want = (params.bands, params.max_features, dim + 1)
        if not isinstance(view, PackedBands) or view.keys.shape != want:
            got = view.keys.shape if isinstance(view, PackedBands) else type(view).__name__
            raise LoopsError(f"{what}: expected packed bands of key shape {want} (preset fast parameters), got {got}")
        return
    if not isinstance(view, HorizonFeatures) or view.descriptor.ndim != 2 or view.descriptor.shape[1] != dim:
        got = view.descriptor.shape[1:] if isinstance(view, HorizonFeatures) else type(view).__name__
        raise LoopsError(f"{what}: descriptors of size {got} do not match the parameters (size {dim})")


def stack_views(views: Sequence[HorizonView], params: HorizonParams) -> PackedSet | None:
    """The stored views laid out for one packed call (None on the per-pair path or with no views)."""
    if not uses_packed(params) or not views:
        return None
    return stack_packed(list(views))


def score_views(test: HorizonView, stored: Sequence[HorizonView], params: HorizonParams,
                stacked: PackedSet | None = None, among: int | None = None) -> np.ndarray:
    """NN+consensus score (score_ransac) of `test` against the first `among` (default all) stored views.
    `stacked`: stack_views(stored) built beforehand (the packed path stacks on the fly without it)."""
    n = len(stored) if among is None else max(0, min(among, len(stored)))
    if n == 0:
        return np.zeros(0)
    if not uses_packed(params):
        return np.array([match(test, s, params).score_ransac for s in stored[:n]])
    db = stacked if stacked is not None else stack_views(stored[:n], params)
    which = None if len(db) == n else np.arange(n)
    return match_packed(test, db, params, which).score_ransac


def match_views(test: HorizonView, stored: Sequence[HorizonView], params: HorizonParams) -> list[HorizonMatch]:
    """Full match results (scores, line, consensus matches) of `test` against each stored view."""
    if not stored:
        return []
    if not uses_packed(params):
        return [match(test, s, params) for s in stored]
    return match_packed(test, stack_views(stored, params), params, details=True).matches


def inlier_columns(result: HorizonMatch, test: HorizonView, stored: HorizonView) -> tuple[np.ndarray, np.ndarray]:
    """Image columns of the consensus matches in the test and the stored view, (M,) each."""
    if isinstance(result, PackedMatch):
        return result.x_test, result.x_stored
    pairs = result.matches[result.inliers]
    return test.x[pairs[:, 0]], stored.x[pairs[:, 1]]
