"""The vocabulary tree under the place-recognition contract (loops.recognition).

VocabRecognizer scores exactly as a VisualMemory does (TF-IDF word histograms, inverted index, the memory's
distance; for BRIEFROT the maximum over the three pattern angles), but grows key by key: the vocabulary is built
beforehand (e.g. the floor vocabulary, loops.vocab.floor_vocabulary) and keys are added as they arrive. A query
among the first n keys scores against the database of those n keys, i.e. the VisualMemory they would make.

VocabVerifier checks a candidate geometrically: mutual nearest-neighbour matches with a ratio test, then a few
RANSAC iterations of a similarity (or affine) transform (loops.geometry).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Hashable, Sequence

import numpy as np

from loops.geometry import GeometryModel, ransac_transform, transform_overlap
from loops.hamming import hamming_matrix
from loops.recognition import Ranked, Verification
from odometry.shared.config import Config, setting

from .database import BowDatabase, EmptyMemoryError
from .features import NoFeaturesError, brief_angles, extract_with_keypoints
from .kinds import DescriptorKind, distances, kind_of
from .memory import VisualMemory, merge_max
from .params import VocabParams
from .tree import VocabularyTree


@dataclass(frozen=True, eq=False)
class VocabObservation:
    """One image as the vocabulary sees it: keypoints and their descriptors (one set per pattern angle of the
    recogniser, the plain pattern first)."""

    keypoints: np.ndarray                  # (N, 2) float32 pixels
    descriptors: tuple[np.ndarray, ...]    # per pattern angle: (N, D) uint8 bits or float32
    image_size: tuple[int, int]            # (width, height)

    def __len__(self) -> int:
        return len(self.keypoints)

    @property
    def nbytes(self) -> int:
        """Bytes a keyframe store would keep (keypoints + descriptors)."""
        return int(self.keypoints.nbytes + sum(d.nbytes for d in self.descriptors))


class VocabRecognizer:
    """Bag-of-words retrieval with prebuilt vocabularies (one per pattern angle of `params`)."""

    def __init__(self, trees: VocabularyTree | Sequence[VocabularyTree], params: VocabParams):
        self.trees = (trees,) if isinstance(trees, VocabularyTree) else tuple(trees)
        self.params = params
        self.angles = brief_angles(params)
        if len(self.trees) != len(self.angles):
            raise ValueError(f"{len(self.trees)} vocabularies for {len(self.angles)} pattern angles "
                             f"({params.descriptor.value})")
        self._keys: list[Hashable] = []
        self._words: list[list[np.ndarray]] = [[] for _ in self.trees]    # per vocabulary, per key
        self._cache: tuple[int, tuple[BowDatabase, ...]] | None = None

    @classmethod
    def from_memory(cls, memory: VisualMemory) -> "VocabRecognizer":
        """The recogniser holding a visual memory's key images (keys = its key names): same rankings."""
        rec = cls(memory.trees, memory.params)
        rec._keys = list(memory.key_names)
        rec._words = [[db.image_words(i) for i in range(len(memory))] for db in memory.databases]
        return rec

    def __len__(self) -> int:
        return len(self._keys)

    def observe(self, image: np.ndarray, mask: np.ndarray | None = None) -> VocabObservation:
        """Keypoints and descriptors of an image; an image without features gives an empty observation."""
        size = (int(image.shape[1]), int(image.shape[0]))
        try:
            xy, descs = extract_with_keypoints(image, self.params, mask, self.angles)
        except NoFeaturesError:
            tree = self.trees[0]
            dtype = np.uint8 if tree.kind is DescriptorKind.BINARY else np.float32
            return VocabObservation(np.zeros((0, 2), np.float32),
                                    tuple(np.zeros((0, tree.dim), dtype) for _ in self.trees), size)
        return VocabObservation(xy, tuple(descs), size)

    def add(self, key: Hashable, observation: VocabObservation) -> None:
        words = [tree.transform(d) for tree, d in zip(self.trees, observation.descriptors)]
        for o, w in enumerate(words):
            self._words[o].append(w)
        self._keys.append(key)

    def _databases(self, n: int) -> tuple[BowDatabase, ...] | None:
        """The key-image databases of the first n keys (the last one is kept: later keys do not change it)."""
        if self._cache is None or self._cache[0] != n:
            try:
                dbs = tuple(BowDatabase.from_words(words[:n], tree.n_words, self.params.distance)
                            for tree, words in zip(self.trees, self._words))
            except EmptyMemoryError:      # the first n keys have no words at all
                dbs = None
            self._cache = (n, dbs)
        return self._cache[1]

    def query(self, observation: VocabObservation, top: int | None = None,
              among: int | None = None) -> list[Ranked]:
        n = len(self._keys) if among is None else min(among, len(self._keys))
        if n <= 0 or len(observation) == 0:
            return []
        dbs = self._databases(n)
        if dbs is None:
            return []
        plain = observation.descriptors[0]
        ranking = merge_max([db.score(tree.transform(plain), self.params.min_shared_words)
                             for tree, db in zip(self.trees, dbs)])
        keys, scores = ranking.keys[:top], ranking.scores[:top]
        return [Ranked(self._keys[int(k)], float(s)) for k, s in zip(keys, scores)]


@dataclass(frozen=True)
class VerifyParams(Config):
    """Geometric check of a vocabulary candidate."""

    ratio: float = setting(0.8, range="(0, 1]",
                           doc="Lowe ratio on descriptor distances (nearest <= ratio x second nearest)")
    min_inliers: int = setting(20, range="[2, inf)", doc="accepted with at least this many matches on one transform")
    threshold_px: float = setting(6.0, range="(0, inf)", unit="px", doc="RANSAC inlier distance")
    iterations: int = setting(200, range="[1, inf)", doc="2-point (similarity) or 3-point (affine) hypotheses")
    geometry: GeometryModel = GeometryModel.SIMILARITY
    scale_range: tuple[float, float] = (1.0 / 6.0, 6.0)   # a downward camera at a fixed height: (0.8, 1.25)
    seed: int = setting(0, range="[0, inf)")


def mutual_ratio_matches(d: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (rows, cols) of a distance matrix that are mutual nearest neighbours and pass the ratio test
    along the rows."""
    if d.shape[0] == 0 or d.shape[1] < 2:
        e = np.zeros(0, np.int64)
        return e, e
    d = np.asarray(d, np.float64)
    rows = np.arange(d.shape[0])
    j = d.argmin(axis=1)
    d1 = d[rows, j]
    d2 = np.partition(d, 1, axis=1)[:, 1]
    ok = (d1 <= ratio * d2) & (d.argmin(axis=0)[j] == rows)
    return rows[ok], j[ok]


class VocabVerifier:
    """Descriptor matching + RANSAC transform between two vocabulary observations."""

    def __init__(self, params: VerifyParams | None = None):
        self.params = params or VerifyParams()

    def verify(self, query: VocabObservation, candidate: VocabObservation) -> Verification:
        p = self.params
        a, b = query.descriptors[0], candidate.descriptors[0]
        if len(a) == 0 or len(b) == 0:
            return Verification(False, 0.0, 0)
        d = hamming_matrix(a, b) if kind_of(a) is DescriptorKind.BINARY else distances(DescriptorKind.FLOAT, a, b)
        ia, ib = mutual_ratio_matches(d, p.ratio)
        xa = query.keypoints[ia].astype(np.float64)
        xb = candidate.keypoints[ib].astype(np.float64)
        mask, predict = ransac_transform(xa, xb, np.ones(len(ia)), p.geometry, p.iterations, p.threshold_px,
                                         seed=p.seed, scale_range=p.scale_range)
        n = int(mask.sum())
        if predict is None:
            return Verification(False, 0.0, 0)
        return Verification(accepted=n >= p.min_inliers, score=float(n), n_inliers=n,
                            inliers_query=query.keypoints[ia[mask]], inliers_candidate=candidate.keypoints[ib[mask]],
                            transform=predict, overlap=transform_overlap(predict, query.image_size,
                                                                         candidate.image_size))
