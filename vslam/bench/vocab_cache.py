"""Caches of `vslam bench localize`: each image's descriptors once per descriptor (and pattern angle), each
vocabulary once per (key images, parameters, seed), with the time each took."""
from __future__ import annotations

import time

import numpy as np

from loops.vocab import NoFeaturesError, VisualMemory, build_tree, extract, extraction_key, vocabulary_seed
from vslam.bench.place_sets import PlaceSet


class Features:
    """Descriptors of the bench's images per (images, index, extraction parameters, pattern angle), with the time
    their extraction took (for queries: the extraction part of the time per query)."""

    def __init__(self) -> None:
        self._d: dict[tuple, tuple[np.ndarray | None, float]] = {}

    def get(self, images_id: str, index: int, image: np.ndarray, mask, params, angles=(0.0,), name: str = "",
            cache: bool = True) -> tuple[list, float]:
        ek = extraction_key(params)
        key = lambda a: (images_id, index, ek, float(a))  # noqa: E731
        missing = tuple(a for a in angles if key(a) not in self._d)
        fresh = {}
        if missing:
            t0 = time.perf_counter()
            try:
                descs = extract(image, params, mask, missing, name=name)
            except NoFeaturesError:
                descs = [None] * len(missing)
            dt = time.perf_counter() - t0
            fresh = {key(a): (d, dt) for a, d in zip(missing, descs)}
            if cache:
                self._d.update(fresh)
        got = [fresh.get(key(a)) or self._d[key(a)] for a in angles]
        return [g[0] for g in got], got[0][1]

    def keys(self, ps: PlaceSet, params, angles, cache: bool = True) -> list[list[np.ndarray]]:
        """per_angle[o][i]: descriptors of key image i under pattern angle o (raises for a featureless key)."""
        per_key = []
        for i, (n, im) in enumerate(ps.keys):
            descs, _ = self.get(ps.keys_id, i, im, None, params, angles, n, cache)
            if descs[0] is None:
                raise NoFeaturesError(f"{n}: no {params.descriptor.value} features in a key image")
            per_key.append(descs)
        return [[d[o] for d in per_key] for o in range(len(angles))]

    def queries(self, ps: PlaceSet, params, indices=None, cache: bool = True) -> list[tuple]:
        """(name, plain-pattern descriptors or None, extraction seconds) of the queries."""
        idx = range(len(ps.queries)) if indices is None else indices
        out = []
        for i in idx:
            n, im, mask = ps.queries[i]
            descs, dt = self.get(ps.queries_id, i, im, mask, params, (0.0,), n, cache)
            out.append((n, descs[0], dt))
        return out


class Vocabularies:
    """Vocabulary trees per (key images, extraction parameters, angle, tree parameters, seed), with build times."""

    def __init__(self) -> None:
        self._d: dict[tuple, tuple] = {}

    @staticmethod
    def key(keys_id: str, params, o: int, angle: float) -> tuple:
        return (keys_id, extraction_key(params), float(angle), params.k, params.depth, params.kmeans_iters,
                params.kmeans_restarts, params.max_train_descriptors, vocabulary_seed(params, o))

    def tree(self, keys_id: str, params, o: int, angle: float, descs: list[np.ndarray], cache: bool = True):
        key = self.key(keys_id, params, o, angle)
        seed = key[-1]
        if key not in self._d:
            t0 = time.perf_counter()
            tree = build_tree(np.concatenate(descs), params.k, params.depth, seed=seed, iters=params.kmeans_iters,
                              max_train=params.max_train_descriptors, restarts=params.kmeans_restarts)
            entry = (tree, time.perf_counter() - t0)
            if not cache:
                return entry
            self._d[key] = entry
        return self._d[key]

    def memory(self, keys_id: str, names, params, per_angle, angles, cache: bool = True):
        """(VisualMemory, seconds of its vocabulary builds + database)."""
        built = [self.tree(keys_id, params, o, a, per_angle[o], cache) for o, a in enumerate(angles)]
        t0 = time.perf_counter()
        memory = VisualMemory.from_trees([t for t, _ in built], per_angle, names, params, angles)
        return memory, sum(s for _, s in built) + time.perf_counter() - t0
