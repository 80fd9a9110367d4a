"""Compact descriptors under the place-recognition contract (loops.recognition).

CdvsRecognizer retrieves by the global descriptor: one vectorised pass over the packed global descriptors of all
eligible keyframes (tiny constant per keyframe, chunked so memory stays bounded). CdvsVerifier is the pairwise
`match` (two-way ratio-tested local matches, DISTRAT, a few RANSAC iterations) with the mode's local-score
threshold and, when given, the loop model's P(loop | score).
"""
from __future__ import annotations

from typing import Hashable

import numpy as np

from loops.cdvs.codec import Descriptor, decode, encode
from loops.cdvs.global_desc import absent_marks, global_scores_many, weight_lut
from loops.cdvs.match import IncompatibleDescriptorsError, match
from loops.cdvs.model import LoopModel
from loops.cdvs.params import CdvsParams
from loops.cdvs.trained import TrainedParams, load_trained
from loops.recognition import Ranked, Verification

_CHUNK = 16384  # rows per vectorised block of the global scan: bounds the temporary memory


class CdvsRecognizer:
    """Global-descriptor retrieval over decoded compact descriptors of one trained parameter set."""

    def __init__(self, mode: int = 4, params: CdvsParams | None = None, trained: TrainedParams | None = None):
        self.mode = mode
        self.params = params or CdvsParams.for_mode(mode)
        self.trained = trained or load_trained()
        k = self.trained.n_clusters
        self._absent = np.zeros((0, k), dtype=np.uint8)   # absent_marks of each keyframe's visited clusters
        self._lut = weight_lut(self.trained.global_weights)
        self._bits = np.zeros((0, k), dtype=np.uint32)
        self._nvis = np.zeros(0, dtype=np.float32)
        self._keys: list[Hashable] = []

    def __len__(self) -> int:
        return len(self._keys)

    def observe(self, image: np.ndarray) -> Descriptor:
        """Encode within the mode's byte budget and decode: exactly what a robot storing the bytes matches."""
        return decode(encode(image, self.mode, self.params, self.trained))

    def check(self, descriptor: Descriptor) -> None:
        """IncompatibleDescriptorsError unless `descriptor` was made with this recogniser's trained parameters."""
        if descriptor.params_id != self.trained.params_id:
            raise IncompatibleDescriptorsError(f"descriptor made with trained parameters {descriptor.params_id:#06x}, "
                                               f"database uses {self.trained.params_id:#06x}")

    def _grow(self) -> None:
        n = len(self._keys)
        cap = max(64, 2 * len(self._nvis))
        for name in ("_absent", "_bits", "_nvis"):
            old = getattr(self, name)
            new = np.zeros((cap,) + old.shape[1:], dtype=old.dtype)
            new[:n] = old[:n]
            setattr(self, name, new)

    def add(self, key: Hashable, observation: Descriptor) -> None:
        self.check(observation)
        i = len(self._keys)
        if i == len(self._nvis):
            self._grow()
        self._absent[i] = absent_marks(observation.global_visited)
        self._bits[i] = observation.global_bits
        self._nvis[i] = observation.global_visited.sum()
        self._keys.append(key)

    def global_scores(self, descriptor: Descriptor, n: int | None = None) -> np.ndarray:
        """Global scores (float32) of `descriptor` against the first `n` stored keyframes (default all)."""
        n = len(self._keys) if n is None else n
        out = np.empty(n, dtype=np.float32)
        w = self.trained.global_weights
        for s in range(0, n, _CHUNK):
            e = min(n, s + _CHUNK)
            out[s:e] = global_scores_many(descriptor.global_visited, descriptor.global_bits, None, self._bits[s:e],
                                          self._nvis[s:e], w, absent_db=self._absent[s:e], lut=self._lut)
        return out

    def query(self, observation: Descriptor, top: int | None = None, among: int | None = None) -> list[Ranked]:
        n = len(self._keys) if among is None else min(among, len(self._keys))
        if n <= 0:
            return []
        g = self.global_scores(observation, n)
        k = n if top is None else min(top, n)
        best = np.argpartition(-g, k - 1)[:k] if k < n else np.arange(n)
        best = best[np.argsort(-g[best], kind="stable")]
        return [Ranked(self._keys[i], float(g[i])) for i in best]


class CdvsVerifier:
    """Pairwise matching; accepted when the local score reaches the threshold (default: the loop model's for the
    mode when a model is given, else the trained per-mode threshold)."""

    def __init__(self, mode: int = 4, params: CdvsParams | None = None, trained: TrainedParams | None = None,
                 model: LoopModel | None = None, threshold: float | None = None):
        self.mode = mode
        self.params = params or CdvsParams.for_mode(mode)
        self.trained = trained or load_trained()
        self.model = model
        if threshold is not None:
            self.threshold = float(threshold)
        elif model is not None:
            self.threshold = float(model.threshold(mode))
        else:
            self.threshold = float(self.trained.local_threshold[mode - 1])

    def verify(self, query: Descriptor, candidate: Descriptor) -> Verification:
        r = match(query, candidate, self.params.matching, self.trained)
        prob = float(self.model.probability(self.mode, r.local_score)) if self.model is not None else None
        return Verification(accepted=r.local_score >= self.threshold, score=r.local_score, n_inliers=r.n_inliers,
                            inliers_query=r.inliers_a, inliers_candidate=r.inliers_b, transform=r.transform,
                            overlap=r.overlap,
                            probability=prob, similarity=float(r.global_score), detail=r)
