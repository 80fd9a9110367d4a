"""1D SURF horizons under the place-recognition contract (loops.recognition).

A horizon is small (tens of features), so retrieval is the full match against every stored horizon, ranked by its
score exactly as LandmarkMemory.recognise ranks landmarks (on the packed path, preset `fast`: every stored view in
one call); the verifier accepts a match whose score reaches the recognition threshold. Needs a camera that sees
the horizon (forward-looking), at a known image row. Extraction and scoring go through loops.horizon.views.
"""
from __future__ import annotations

from typing import Hashable

import numpy as np

from loops.horizon.memory import LandmarkMemory
from loops.horizon.params import HorizonParams
from loops.horizon.signal import HorizonLine
from loops.horizon.views import HorizonView, check_view, extract_view, inlier_columns, match_views
from loops.recognition import Ranked, Verification


class HorizonRecognizer:
    """Retrieval over stored horizons (a LandmarkMemory whose landmark names are the keys as text)."""

    def __init__(self, horizon: float | HorizonLine, params: HorizonParams | None = None,
                 memory: LandmarkMemory | None = None):
        self.horizon = horizon                 # image row (or line) of the horizon in the images observed
        self.memory = memory if memory is not None else LandmarkMemory(params or HorizonParams())
        self.params = self.memory.params
        self._keys: list[Hashable] = list(self.memory.names)

    def __len__(self) -> int:
        return len(self._keys)

    def observe(self, image: np.ndarray) -> HorizonView:
        return extract_view(image, self.horizon, self.params)

    def add(self, key: Hashable, observation: HorizonView) -> None:
        self.memory.add(str(key), observation)
        self._keys.append(key)

    def query(self, observation: HorizonView, top: int | None = None,
              among: int | None = None) -> list[Ranked]:
        n = len(self._keys) if among is None else min(among, len(self._keys))
        if n <= 0:
            return []
        scores = self.memory.scores(observation, n)
        order = np.argsort(-scores, kind="stable")[:top]
        return [Ranked(self._keys[i], float(scores[i])) for i in order]


class HorizonVerifier:
    """NN + RANSAC line fit (packed path: NN + shift window per band); accepted when the score reaches the
    threshold (default params.recognition_threshold). Inliers are horizon columns (D = 1); the transform is the
    line (b_s, b_d)."""

    def __init__(self, params: HorizonParams | None = None, threshold: float | None = None):
        self.params = params or HorizonParams()
        self.threshold = self.params.recognition_threshold if threshold is None else float(threshold)

    def verify(self, query: HorizonView, candidate: HorizonView) -> Verification:
        check_view(query, self.params, "query view")
        check_view(candidate, self.params, "candidate view")
        r = match_views(query, [candidate], self.params)[0]
        xq, xc = inlier_columns(r, query, candidate)
        fitted = bool(np.isfinite(r.b_s))
        return Verification(accepted=fitted and r.score_ransac >= self.threshold, score=r.score_ransac,
                            n_inliers=r.n_inliers, inliers_query=xq.reshape(-1, 1),
                            inliers_candidate=xc.reshape(-1, 1),
                            transform=(r.b_s, r.b_d) if fitted else None, detail=r)
