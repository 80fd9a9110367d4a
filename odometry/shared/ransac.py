"""The one RANSAC loop of the toolkit: draw minimal samples, score hypotheses in vectorised batches, keep the best
consensus, then refit it. The rigid floor fit (odometry.rigid), the similarity / affine check of loop candidates
(loops.geometry) and the horizon line fit (loops.horizon.matching) all run on it.

Each caller supplies two functions: `draw(k)` makes k hypotheses from k minimal samples (drawing from a generator
the caller seeded, so a result depends only on the input) and `evaluate(hypotheses)` returns their consensus scores
(inlier count or inlier weight sum) and their inlier matrix. Scoring is batched because a (hypotheses x points)
residual matrix costs one numpy pass where a Python loop would cost one per hypothesis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Generic, TypeVar

import numpy as np

H = TypeVar("H")
M = TypeVar("M")


@dataclass(frozen=True)
class Consensus(Generic[H]):
    """The winning hypothesis: `hypotheses` is the batch it came from, `index` its position in that batch."""

    hypotheses: H
    index: int
    score: float           # its consensus score (as `evaluate` computed it: count or weight sum)
    inliers: np.ndarray    # its row of the batch's inlier matrix
    drawn: int             # hypotheses drawn in all


def sample_pairs(rng: np.random.Generator, n: int, k: int, *, cyclic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """k index pairs (i, j), i != j, uniform over 0..n-1 (n >= 2). Two ways of turning the second draw r into j
    exist, each fixed by the results callers have published: j = r skipping i (default), or j = i + 1 + r mod n
    (`cyclic`). Both take the same two draws from `rng`."""
    i = rng.integers(0, n, k)
    r = rng.integers(0, n - 1, k)
    j = (i + 1 + r) % n if cyclic else r + (r >= i)
    return i, j


def all_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every index pair i < j of n items (exhaustive hypotheses when there are few)."""
    return np.triu_indices(n, 1)


def sample_subsets(rng: np.random.Generator, k: int, n: int, size: int) -> np.ndarray:
    """(k, size) minimal samples of distinct indices out of n: the first `size` of a random permutation each."""
    return np.argsort(rng.random((k, n)), axis=1)[:, :size]


def iterations_needed(inlier_ratio: float, sample_size: int, confidence: float, drawn: int) -> int:
    """Hypotheses to draw so that, with probability `confidence`, one sample was all inliers (`drawn` when the
    consensus is already perfect)."""
    all_in = 1.0
    for _ in range(sample_size):
        all_in *= inlier_ratio
    p_fail = 1.0 - all_in
    if p_fail <= 0:
        return drawn
    return int(math.ceil(math.log(1 - confidence) / math.log(max(p_fail, 1e-12))))


def find_consensus(draw: Callable[[int], H], evaluate: Callable[[H], tuple[np.ndarray, np.ndarray]],
                   max_iterations: int, *, batch: int | None = None, better_than: float = -np.inf,
                   confidence: float | None = None, n_data: int = 0, sample_size: int = 2) -> Consensus[H] | None:
    """The hypothesis with the highest consensus score, drawn in batches of `batch` (default: all at once).

    A batch's best replaces the current one only when strictly better (the first hypothesis wins ties), and only
    when better than `better_than`. With `confidence`, drawing stops early once that many hypotheses were drawn
    as `iterations_needed` asks for the current best's inlier ratio (out of `n_data` points). An empty batch (every
    sample degenerate) is skipped. None when no hypothesis beat `better_than`."""
    batch = max_iterations if batch is None else batch
    best: Consensus[H] | None = None
    best_score = better_than
    needed, drawn = max_iterations, 0
    while drawn < min(needed, max_iterations):
        k = min(batch, max_iterations - drawn)
        hypotheses = draw(k)
        drawn += k
        scores, inliers = evaluate(hypotheses)
        if len(scores) == 0:
            continue
        h = int(np.argmax(scores))
        if scores[h] > best_score:
            best_score = scores[h]
            best = Consensus(hypotheses, h, best_score, inliers[h], drawn)
            if confidence is not None:
                needed = iterations_needed(best_score / n_data, sample_size, confidence, drawn)
    if best is None:
        return None
    return Consensus(best.hypotheses, best.index, best.score, best.inliers, drawn)


def refit_if_not_worse(inliers: np.ndarray, refit: Callable[[np.ndarray], tuple[M, np.ndarray] | None],
                       score: Callable[[np.ndarray], float]) -> tuple[M, np.ndarray] | None:
    """One least-squares refit on the consensus set: `refit(inliers)` -> (model, its inliers), or None when the
    refitted model is implausible. Returned only when its inliers score at least as well as the consensus set's;
    otherwise None (the caller keeps the minimal-sample model)."""
    fitted = refit(inliers)
    if fitted is None or score(fitted[1]) < score(inliers):
        return None
    return fitted


def refine_iteratively(model: M, inliers_of: Callable[[M], np.ndarray], fit: Callable[[np.ndarray], M],
                       rounds: int, min_inliers: int, n: int) -> tuple[M, np.ndarray]:
    """Alternate inlier re-selection and least-squares fitting for up to `rounds` rounds, stopping when the inlier
    set no longer changes or falls below `min_inliers`. Returns the last model and the inliers it was fitted to
    (all False when the first re-selection already had too few)."""
    inliers = np.zeros(n, dtype=bool)
    for _ in range(max(1, rounds)):
        new = inliers_of(model)
        if new.sum() < min_inliers:
            break
        if np.array_equal(new, inliers):
            break
        inliers = new
        model = fit(inliers)
    return model, inliers
