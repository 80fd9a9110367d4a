"""The place-recognition contract every recogniser of `loops` implements.

Recognition is two separate steps:

    retrieval     Recognizer: observe(image) -> observation; add(key, observation); query(observation) -> ranked
                  candidates (key, score), best first. Cheap, approximate, over the whole database.
    verification  Verifier: verify(query observation, candidate observation) -> Verification (inliers, fitted
                  transform, accepted). Expensive, geometric, on a shortlist only.

The implementations are thin adapters over each system's own classes:

    loops.cdvs.recognizer     CdvsRecognizer, CdvsVerifier        compact descriptors (LoopDatabase's scoring)
    loops.vocab.recognizer    VocabRecognizer, VocabVerifier      vocabulary tree bag of words (VisualMemory's)
    loops.horizon.recognizer  HorizonRecognizer, HorizonVerifier  1D SURF on the horizon (LandmarkMemory's)

`loops.loop_detector.LoopDetector` combines a recogniser and a verifier with one acceptance policy (recent-key
exclusion, shortlist, confirmation) into a loop detector for an image stream.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Hashable, Protocol, TypeVar

import numpy as np

Obs = TypeVar("Obs")


@dataclass(frozen=True)
class Ranked:
    """A retrieval candidate: a stored key and its score (higher = more alike; scales differ per recogniser)."""

    key: Hashable
    score: float


def _no_points() -> np.ndarray:
    return np.zeros((0, 2), np.float32)


@dataclass(frozen=True)
class Verification:
    """The geometric check of one (query, candidate) pair.

    accepted: the verifier's verdict (enough consistent inliers / score above its threshold).
    score: its evidence, higher = stronger (cdvs: summed inlier weights; vocab: inlier count; horizon: NN+RANSAC
        score); the scale is the verifier's own.
    inliers_query, inliers_candidate: (K, D) coordinates of the inlier features in each observation (image pixels,
        D = 2; for a horizon the column, D = 1).
    transform: the fitted model, in the verifier's own form (a predict(points) function for image transforms,
        (b_s, b_d) for a horizon line); None when nothing was fitted.
    overlap: image overlap the transform implies (0 when unknown).
    probability: P(true loop | score) when the verifier has a calibrated model, else None.
    similarity: the pair's appearance similarity recomputed by the verifier at full precision (cdvs: the global
        descriptor score), None when the verifier does not compute one.
    detail: the system's own match result (e.g. loops.cdvs.MatchResult), for callers that need more.
    """

    accepted: bool
    score: float
    n_inliers: int
    inliers_query: np.ndarray = field(default_factory=_no_points)
    inliers_candidate: np.ndarray = field(default_factory=_no_points)
    transform: Any = None
    overlap: float = 0.0
    probability: float | None = None
    similarity: float | None = None
    detail: Any = None


class Recognizer(Protocol[Obs]):
    """Retrieval over observations stored under keys."""

    def observe(self, image: np.ndarray) -> Obs:
        """The observation of an image (what is stored and compared)."""
        ...

    def add(self, key: Hashable, observation: Obs) -> None:
        """Store an observation under a new key."""
        ...

    def query(self, observation: Obs, top: int | None = None, among: int | None = None) -> list[Ranked]:
        """Stored keys ranked by similarity to `observation`, best first (ties: the earlier-added key first), at
        most `top` of them, among the first `among` keys added (default all). [] for an empty database."""
        ...

    def __len__(self) -> int:
        ...


class Verifier(Protocol[Obs]):
    """Geometric verification of a retrieved candidate, separate from retrieval."""

    def verify(self, query: Obs, candidate: Obs) -> Verification:
        ...
