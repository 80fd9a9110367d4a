"""1D SURF horizons under the place-recognition contract (loops.recognition).

A horizon is small (tens of features), so retrieval is the full NN + RANSAC match against every stored horizon,
ranked by its score exactly as LandmarkMemory.recognise ranks landmarks; the verifier accepts a match whose score
reaches the recognition threshold. Needs a camera that sees the horizon (forward-looking), at a known image row.
"""
from __future__ import annotations

from typing import Hashable

import numpy as np

from loops.horizon.matching import match
from loops.horizon.memory import LandmarkMemory
from loops.horizon.params import HorizonParams
from loops.horizon.signal import HorizonLine
from loops.horizon.surf1d import HorizonFeatures, extract_features
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

    def observe(self, image: np.ndarray) -> HorizonFeatures:
        return extract_features(image, self.horizon, self.params)

    def add(self, key: Hashable, observation: HorizonFeatures) -> None:
        self.memory.add(str(key), observation)
        self._keys.append(key)

    def query(self, observation: HorizonFeatures, top: int | None = None,
              among: int | None = None) -> list[Ranked]:
        n = len(self._keys) if among is None else min(among, len(self._keys))
        if n <= 0:
            return []
        scores = np.array([match(observation, lm.features, self.params).score_ransac
                           for lm in self.memory.landmarks[:n]])
        order = np.argsort(-scores, kind="stable")[:top]
        return [Ranked(self._keys[i], float(scores[i])) for i in order]


class HorizonVerifier:
    """NN + RANSAC line fit; accepted when the score reaches the threshold (default params.recognition_threshold).
    Inliers are horizon columns (D = 1); the transform is the line (b_s, b_d)."""

    def __init__(self, params: HorizonParams | None = None, threshold: float | None = None):
        self.params = params or HorizonParams()
        self.threshold = self.params.recognition_threshold if threshold is None else float(threshold)

    def verify(self, query: HorizonFeatures, candidate: HorizonFeatures) -> Verification:
        r = match(query, candidate, self.params)
        pairs = r.matches[r.inliers]
        fitted = bool(np.isfinite(r.b_s))
        return Verification(accepted=fitted and r.score_ransac >= self.threshold, score=r.score_ransac,
                            n_inliers=r.n_inliers, inliers_query=query.x[pairs[:, 0]].reshape(-1, 1),
                            inliers_candidate=candidate.x[pairs[:, 1]].reshape(-1, 1),
                            transform=(r.b_s, r.b_d) if fitted else None, detail=r)
