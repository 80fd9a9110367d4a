"""Evaluation of visual-memory localisation: the paper's mu1 / mu2 rank metrics (eqs. 3-4), effectiveness,
Recall@N and repeatability over vocabulary rebuilds (Table 8); the precision-recall curve over top-1 scores is
loops.curves.pr_curve.

Convention for key images left out of a ranking (they share fewer than min_shared words with the query): they
tie for the remaining places, so each gets the average of those ranks, (m + 1 + n) / 2 with m ranked of n keys.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loops.curves import pr_curve
from loops.errors import LoopsError


def full_ranks(ranked_keys: np.ndarray, n_keys: int) -> np.ndarray:
    """1-based rank of every key image given the ranked candidate list (unranked keys share the tail's mean)."""
    m = len(ranked_keys)
    ranks = np.full(n_keys, (m + 1 + n_keys) / 2.0)
    ranks[np.asarray(ranked_keys, np.int64)] = np.arange(1, m + 1)
    return ranks


def mu1(ranked_keys: np.ndarray, true_keys, n_keys: int) -> float:
    """Eq. 3: rank of the ground-truth key image (the best-ranked one when several are true)."""
    return float(full_ranks(ranked_keys, n_keys)[np.asarray(list(true_keys), np.int64)].min())


def mu2(ranked_keys: np.ndarray, key_similarity: np.ndarray, n_keys: int) -> float:
    """Eq. 4: sum over key images l of z_l(I*_k) / sum_l' z_l'(I*_k) * rank(l), where key_similarity[l] =
    z_l(I*_k) is the similarity of key image l to the true key image k (VisualMemory.key_similarity: 1 for k
    itself, 0 for keys that share too few words with it). Near-duplicates of the true key ranked high keep mu2
    low; mu2 = mu1 when the true key resembles no other key. Unranked keys take the mean of the remaining ranks
    (full_ranks)."""
    z = np.asarray(key_similarity, float)
    total = z.sum()
    if total <= 0:
        raise LoopsError("mu2 needs a true key image with non-zero self-similarity")
    return float((z / total) @ full_ranks(ranked_keys, n_keys))


def recall_at(ranked_keys: np.ndarray, true_keys, n: int) -> bool:
    """True when a ground-truth key image is among the first n ranked candidates."""
    return bool(np.isin(np.asarray(ranked_keys[:n]), np.asarray(list(true_keys))).any())


def repeatability(top1: np.ndarray) -> float:
    """Table 8: top1[r, q] = key image ranked first for query q with vocabulary build r. For each query, the share
    of builds giving its most frequent answer; averaged over queries (1.0 = every build agrees)."""
    top1 = np.asarray(top1)
    if top1.ndim != 2 or top1.shape[0] == 0:
        raise LoopsError("repeatability needs a (builds, queries) array")
    shares = []
    for q in range(top1.shape[1]):
        _, counts = np.unique(top1[:, q], return_counts=True)
        shares.append(counts.max() / top1.shape[0])
    return float(np.mean(shares))


@dataclass(frozen=True)
class Summary:
    """One row of the paper's Tables 2-7 plus Recall@1/5 and average precision."""

    n_tests: int
    correct_mu1: int
    correct_mu2: int | None      # None when mu2 is not available (a memory without key-to-key similarities)
    recall1: float
    recall5: float
    average_precision: float
    median_ms: float

    @property
    def eff_mu1(self) -> float:
        return 100.0 * self.correct_mu1 / max(self.n_tests, 1)

    @property
    def eff_mu2(self) -> float:
        return float("nan") if self.correct_mu2 is None else 100.0 * self.correct_mu2 / max(self.n_tests, 1)


def summarise(mu1s, mu2s, recall1s, recall5s, top_scores, top_correct, times_s, mu2_threshold: float = 2.5
              ) -> Summary:
    mu1s, mu2s = np.asarray(mu1s, float), np.asarray(mu2s, float)
    pr = pr_curve(top_scores, top_correct)
    correct_mu2 = None if len(mu2s) and np.isnan(mu2s).all() else int((mu2s < mu2_threshold).sum())
    return Summary(len(mu1s), int((mu1s == 1).sum()), correct_mu2,
                   float(np.mean(recall1s)) if len(mu1s) else float("nan"),
                   float(np.mean(recall5s)) if len(mu1s) else float("nan"), pr.average_precision,
                   float(np.median(times_s)) * 1e3 if len(times_s) else float("nan"))
