"""Run a query set against a visual memory and score it with the paper's metrics (Tables 2-7 layout)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Iterable, Mapping, Sequence

import numpy as np

from loops.curves import PRCurve, pr_curve

from .features import NoFeaturesError
from .memory import Ranking, VisualMemory
from .metrics import Summary, mu1, mu2, recall_at, summarise

_EMPTY = Ranking(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64))


@dataclass(frozen=True)
class QueryResult:
    name: str
    ranking: Ranking
    true_keys: tuple[int, ...]
    seconds: float
    mu1: float = float("nan")
    mu2: float = float("nan")
    error: str = ""


@dataclass
class Evaluation:
    memory_size: int
    results: list[QueryResult] = field(default_factory=list)

    @property
    def scored(self) -> list[QueryResult]:
        """Queries that have ground truth."""
        return [r for r in self.results if r.true_keys]

    def summary(self) -> Summary:
        s = self.scored
        return summarise([r.mu1 for r in s], [r.mu2 for r in s],
                         [recall_at(r.ranking.keys, r.true_keys, 1) for r in s],
                         [recall_at(r.ranking.keys, r.true_keys, 5) for r in s],
                         *self._top(), [r.seconds for r in self.results])

    def _top(self) -> tuple[np.ndarray, np.ndarray]:
        s = self.scored
        scores = np.array([r.ranking.scores[0] if len(r.ranking) else -np.inf for r in s])
        correct = np.array([len(r.ranking) > 0 and int(r.ranking.keys[0]) in r.true_keys for r in s], bool)
        return scores, correct

    def pr(self) -> PRCurve:
        return pr_curve(*self._top())

    def winner_counts(self, n_vocab: int) -> np.ndarray:
        """How often each vocabulary gave the top-1 score (the paper's Figs. 12-13, for BRIEFROT)."""
        w = [int(r.ranking.vocab[0]) for r in self.results if len(r.ranking)]
        return np.bincount(np.asarray(w, np.int64), minlength=n_vocab)

    def ranking_rows(self, key_names: Sequence[str]) -> list[tuple[str, int, str, float]]:
        """(query, rank, key, score) rows, rank 1 = best."""
        return [(r.name, i + 1, key_names[int(k)], float(s))
                for r in self.results for i, (k, s) in enumerate(zip(r.ranking.keys, r.ranking.scores))]


def evaluate(memory: VisualMemory, queries: Iterable[tuple[str, np.ndarray, np.ndarray | None]],
             truth: Mapping[str, Sequence[int]]) -> Evaluation:
    """queries yields (name, image, mask or None); truth maps a query name to its true key indices. The time per
    query is feature extraction + scoring (image decoding excluded). A query without features, or given as None
    (unreadable), is a miss."""
    def ranked():
        for name, image, mask in queries:
            t0 = time.perf_counter()
            try:
                if image is None:
                    raise NoFeaturesError(f"{name}: unreadable image")
                ranking, error = memory.query(image, mask, name=name), ""
            except NoFeaturesError as exc:
                ranking, error = _EMPTY, str(exc)
            yield name, ranking, time.perf_counter() - t0, error

    return score_rankings(memory, ranked(), truth)


def evaluate_descriptors(memory, queries: Iterable[tuple[str, np.ndarray | None, float]],
                         truth: Mapping[str, Sequence[int]]) -> Evaluation:
    """Like evaluate() for descriptors extracted beforehand: queries yields (name, plain-pattern descriptors or
    None when the image had none, seconds the extraction took); the time per query is that plus the scoring.
    `memory` is anything with query_descriptors() and __len__ (key_similarity() too, for mu2)."""
    def ranked():
        for name, descriptors, extract_s in queries:
            if descriptors is None or len(descriptors) == 0:
                yield name, _EMPTY, extract_s, f"{name}: no features"
                continue
            t0 = time.perf_counter()
            ranking = memory.query_descriptors(descriptors)
            yield name, ranking, extract_s + time.perf_counter() - t0, ""

    return score_rankings(memory, ranked(), truth)


def score_rankings(memory, rankings: Iterable[tuple[str, Ranking, float, str]],
                   truth: Mapping[str, Sequence[int]]) -> Evaluation:
    """mu1 (eq. 3) and mu2 (eq. 4) of each (name, ranking, seconds, error). mu2 weighs the ranks by the key images'
    similarity to the true key, z_l(I*_k) = memory.key_similarity(k); with several true keys the best (lowest)
    mu1 and mu2 count. A memory without key_similarity() (a foreign implementation) gets mu2 = nan."""
    n = len(memory)
    out = Evaluation(n)
    z_cache: dict[int, np.ndarray] = {}
    has_z = hasattr(memory, "key_similarity")

    def z_of(k: int) -> np.ndarray:
        if k not in z_cache:
            z_cache[k] = memory.key_similarity(k)
        return z_cache[k]

    for name, ranking, seconds, error in rankings:
        true = tuple(int(t) for t in truth.get(name, ()))
        if true:
            m1 = mu1(ranking.keys, true, n)
            m2 = min(mu2(ranking.keys, z_of(k), n) for k in true) if has_z else float("nan")
            out.results.append(QueryResult(name, ranking, true, seconds, m1, m2, error))
        else:
            out.results.append(QueryResult(name, ranking, true, seconds, error=error))
    return out
