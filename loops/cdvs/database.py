"""Loop database: index descriptors as keyframes arrive, answer "which earlier keyframes match this one".

Query = global shortlist over all eligible keyframes (one vectorised pass over packed global descriptors, tiny
constant per keyframe, chunked so memory stays bounded), then local matching + geometric check on the top
candidates only. The most recent keyframes are skipped; a loop can be required to be confirmed by consecutive
query keyframes matching the same place before it is accepted (DLoopDetector / ORB-SLAM style).
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from loops.cdvs.codec import Descriptor
from loops.cdvs.global_desc import absent_marks, global_scores_many, weight_lut
from loops.cdvs.match import IncompatibleDescriptorsError, MatchResult, match
from loops.cdvs.params import CdvsParams
from loops.cdvs.trained import TrainedParams, load_trained
from odometry.shared.config import Config, setting

_CHUNK = 16384  # rows per vectorised block of the global scan: bounds the temporary memory


@dataclass(frozen=True)
class DatabaseParams(Config):
    shortlist: int = setting(5, range="[1, inf)", doc="candidates (best global scores) verified by local matching")
    exclude_recent: int = setting(20, range="[0, inf)",
                                  doc="the most recently added keyframes are never candidates")
    min_global: float = setting(-1.0, doc="candidates below this global score are not verified")
    confirmations: int = setting(1, range="[1, inf)",
                                 doc="consecutive query keyframes that must agree before a loop is accepted")
    confirm_window: int = setting(5, range="[0, inf)",
                                  doc='"agree": a verified match within this many stored keyframes of the last one')
    min_overlap: float | None = setting(None, range="[0, 1]")   # accept only if the verified transform implies at
    #                                     least this image overlap; None: the model's min_overlap (0 without a model)


@dataclass(frozen=True)
class Candidate:
    frame_id: int                  # the stored keyframe's id
    global_score: float
    local_score: float
    n_inliers: int
    match: MatchResult             # inlier pixel pairs: query keypoints in inliers_a, stored in inliers_b
    passes: bool                   # local score >= the acceptance threshold (and overlap >= min_overlap)
    confirmed: bool                # passes and confirmed by the previous query keyframes
    probability: float | None      # P(loop | local score) when the database has a LoopModel

    @property
    def accepted(self) -> bool:
        return self.passes and self.confirmed


class LoopDatabase:
    """Keyframe database for one descriptor mode."""

    def __init__(self, mode: int, params: CdvsParams | None = None, db_params: DatabaseParams | None = None,
                 model=None, trained: TrainedParams | None = None, threshold: float | None = None):
        self.mode = mode
        self.params = params or CdvsParams.for_mode(mode)
        self.db = db_params or DatabaseParams()
        self.trained = trained or load_trained()
        self.model = model
        if threshold is not None:
            self.threshold = float(threshold)
        elif model is not None:
            self.threshold = float(model.threshold(mode))
        else:
            self.threshold = float(self.trained.local_threshold[mode - 1])
        if self.db.min_overlap is not None:
            self.min_overlap = float(self.db.min_overlap)
        else:
            self.min_overlap = float(getattr(model, "min_overlap", None) or 0.0)
        k = self.trained.n_clusters
        self._absent = np.zeros((0, k), dtype=np.uint8)   # absent_marks of each keyframe's visited clusters
        self._lut = weight_lut(self.trained.global_weights)
        self._bits = np.zeros((0, k), dtype=np.uint32)
        self._nvis = np.zeros(0, dtype=np.float32)
        self._ids = np.zeros(0, dtype=np.int64)
        self._descs: list[Descriptor] = []
        self._n = 0
        self._history: deque[list[int]] = deque(maxlen=max(1, self.db.confirmations - 1))

    def __len__(self) -> int:
        return self._n

    def _grow(self) -> None:
        cap = max(64, 2 * len(self._ids))
        for name in ("_absent", "_bits", "_nvis", "_ids"):
            old = getattr(self, name)
            new = np.zeros((cap,) + old.shape[1:], dtype=old.dtype)
            new[: self._n] = old[: self._n]
            setattr(self, name, new)

    def add(self, frame_id: int, descriptor: Descriptor) -> None:
        """Store a keyframe's descriptor (frame ids must increase)."""
        if descriptor.params_id != self.trained.params_id:
            raise IncompatibleDescriptorsError(f"descriptor made with trained parameters {descriptor.params_id:#06x}, "
                                               f"database uses {self.trained.params_id:#06x}")
        if self._n and frame_id <= self._ids[self._n - 1]:
            raise ValueError(f"frame ids must increase: {frame_id} after {int(self._ids[self._n - 1])}")
        if self._n == len(self._ids):
            self._grow()
        i = self._n
        self._absent[i] = absent_marks(descriptor.global_visited)
        self._bits[i] = descriptor.global_bits
        self._nvis[i] = descriptor.global_visited.sum()
        self._ids[i] = frame_id
        self._descs.append(descriptor)
        self._n += 1

    def global_scores(self, descriptor: Descriptor, n: int | None = None) -> np.ndarray:
        """Global scores of `descriptor` against the first `n` stored keyframes (default all)."""
        n = self._n if n is None else n
        out = np.empty(n, dtype=np.float32)
        w = self.trained.global_weights
        for s in range(0, n, _CHUNK):
            e = min(n, s + _CHUNK)
            out[s:e] = global_scores_many(descriptor.global_visited, descriptor.global_bits, None, self._bits[s:e],
                                          self._nvis[s:e], w, absent_db=self._absent[s:e], lut=self._lut)
        return out

    def query(self, descriptor: Descriptor, frame_id: int | None = None) -> list[Candidate]:
        """Verified candidates for `descriptor`, best local score first. Only keyframes added before the last
        `exclude_recent` (and, if `frame_id` is given, with smaller ids) are considered."""
        n = self._n - self.db.exclude_recent
        if frame_id is not None and n > 0:
            n = min(n, int(np.searchsorted(self._ids[: self._n], frame_id)) - self.db.exclude_recent)
        out: list[Candidate] = []
        if n > 0:
            g = self.global_scores(descriptor, n)
            k = min(self.db.shortlist, n)
            top = np.argpartition(-g, k - 1)[:k] if k < n else np.arange(n)
            top = top[np.argsort(-g[top], kind="stable")]
            for i in top:
                if g[i] < self.db.min_global:
                    continue
                r = match(descriptor, self._descs[i], self.params.matching, self.trained)
                out.append((int(i), r))
        passing = [i for i, r in out if self._passes(r)]
        cands = []
        for i, r in out:
            passes = self._passes(r)
            confirmed = passes and self._confirmed(i)
            prob = float(self.model.probability(self.mode, r.local_score)) if self.model is not None else None
            cands.append(Candidate(int(self._ids[i]), float(r.global_score), r.local_score, r.n_inliers, r, passes,
                                   confirmed, prob))
        self._history.append(passing)
        cands.sort(key=lambda c: -c.local_score)
        return cands

    def _passes(self, r: MatchResult) -> bool:
        return r.local_score >= self.threshold and (self.min_overlap <= 0.0 or r.overlap >= self.min_overlap)

    def _confirmed(self, index: int) -> bool:
        need = self.db.confirmations - 1
        if need <= 0:
            return True
        if len(self._history) < need:
            return False
        w = self.db.confirm_window
        return all(any(abs(j - index) <= w for j in prev) for prev in list(self._history)[-need:])
