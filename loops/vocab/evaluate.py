"""Run a query set against a visual memory and score it with the paper's metrics (Tables 2-7 layout)."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from .features import NoFeaturesError
from .memory import Ranking, VisualMemory
from .metrics import Summary, mu1, mu2, pr_curve, recall_at, summarise


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

    def pr(self):
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
             truth: Mapping[str, Sequence[int]], key_image: Callable[[int], np.ndarray] | None = None,
             key_descriptors: Callable[[int], np.ndarray] | None = None) -> Evaluation:
    """queries yields (name, image, mask or None); truth maps a query name to its true key indices. For mu2's
    key-to-key similarities z_l(I*_k), key k is itself queried against the memory: pass key_image(k) (its image),
    or key_descriptors(k) (its plain-pattern descriptors, saves re-extracting them). The time per query is feature
    extraction + scoring (image decoding excluded)."""
    if key_image is None and key_descriptors is None:
        raise ValueError("evaluate needs key_image or key_descriptors for mu2")
    n = len(memory)
    out = Evaluation(n)
    self_sim: dict[int, np.ndarray] = {}

    def z_of(k: int) -> np.ndarray:
        if k not in self_sim:
            try:
                if key_descriptors is not None:
                    self_sim[k] = memory.query_descriptors(key_descriptors(k)).dense_scores(n)
                else:
                    self_sim[k] = memory.query(key_image(k), name=memory.key_names[k]).dense_scores(n)
            except NoFeaturesError:
                self_sim[k] = np.zeros(n)
            if self_sim[k].sum() <= 0:
                self_sim[k][k] = 1.0  # a key with no usable words only resembles itself
        return self_sim[k]

    for name, image, mask in queries:
        true = tuple(int(t) for t in truth.get(name, ()))
        t0 = time.perf_counter()
        try:
            ranking, error = memory.query(image, mask, name=name), ""
        except NoFeaturesError as exc:
            ranking, error = Ranking(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)), str(exc)
        dt = time.perf_counter() - t0
        if true:
            m1 = mu1(ranking.keys, true, n)
            m2 = min(mu2(ranking.keys, z_of(k), n) for k in true)
            out.results.append(QueryResult(name, ranking, true, dt, m1, m2, error))
        else:
            out.results.append(QueryResult(name, ranking, true, dt, error=error))
    return out
