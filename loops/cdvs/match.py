"""Pairwise matching of two compact descriptors: global score, two-way ratio-tested local matches, DISTRAT and a
few RANSAC iterations; the local score is the sum of the match weights of the surviving inliers."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from loops.cdvs.codec import Descriptor
from loops.cdvs.geometry import distrat_inliers, ransac
from loops.cdvs.global_desc import global_score
from loops.cdvs.params import MatchParams
from loops.cdvs.trained import TrainedParams, load_trained


class IncompatibleDescriptorsError(ValueError):
    """The two descriptors were made with different trained parameters and cannot be compared."""


@dataclass(frozen=True)
class MatchResult:
    global_score: float
    local_score: float          # sum of match weights over the geometrically verified inliers
    n_matches: int              # tentative (ratio-tested, two-way) matches
    n_inliers: int
    inliers_a: np.ndarray       # (K, 2) float32 inlier keypoints in original pixels of image a
    inliers_b: np.ndarray       # (K, 2) float32 corresponding keypoints in image b
    inlier_weights: np.ndarray  # (K,)


def _nearest_two(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row of a: index of the nearest row of b, its Hamming distance and the second-nearest distance.
    OpenCV's SIMD Hamming (no BLAS: a GEMM would spin up OpenBLAS threads on a busy machine)."""
    dist, idx = cv2.batchDistance(a, b, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=2)
    dist = dist.astype(np.float64)
    return idx[:, 0].astype(np.int64), dist[:, 0], dist[:, 1]


def _one_way(j: np.ndarray, d1: np.ndarray, d2: np.ndarray, ratio: float,
             max_d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ok = (d1 <= ratio * d2) & (d1 <= max_d) & (d2 > 0) & (j >= 0)
    i = np.flatnonzero(ok)
    w = np.cos(0.5 * np.pi * np.sqrt(d1[i] / d2[i]))
    # keep, for each matched column, only its best-weighted row
    o = np.argsort(-w, kind="stable")
    _, first = np.unique(j[i][o], return_index=True)
    sel = o[first]
    return i[sel], j[i][sel], w[sel]


def local_matches(a: Descriptor, b: Descriptor, p: MatchParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two-way ratio-tested matches (ia, ib, weights), CDVS-style union of both directions."""
    if a.n_local < 2 or b.n_local < 2:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    n_bytes = min(a.local.shape[1], b.local.shape[1])   # priority-ordered bits: compare the common prefix
    la = np.ascontiguousarray(a.local[:, :n_bytes])
    lb = np.ascontiguousarray(b.local[:, :n_bytes])
    max_d = p.max_distance_frac * 8 * n_bytes
    i1, j1, w1 = _one_way(*_nearest_two(la, lb), p.ratio, max_d)
    j2, i2, w2 = _one_way(*_nearest_two(lb, la), p.ratio, max_d)
    nb = b.n_local
    k1, k2 = i1 * nb + j1, i2 * nb + j2
    both, x1, x2 = np.intersect1d(k1, k2, return_indices=True)
    only1 = np.setdiff1d(np.arange(len(k1)), x1)
    only2 = np.setdiff1d(np.arange(len(k2)), x2)
    w_both = 0.5 * (w1[x1] + w2[x2])
    w_one = np.concatenate([w1[only1], w2[only2]])
    if len(w_one) > len(both) and len(w_one):
        w_one = w_one * (len(both) / len(w_one))
    keys = np.concatenate([both, k1[only1], k2[only2]])
    w = np.concatenate([w_both, w_one])
    return keys // nb, keys % nb, w


def match(a: Descriptor, b: Descriptor, params: MatchParams | None = None,
          trained: TrainedParams | None = None) -> MatchResult:
    """Compare two descriptors (any modes made with the same trained parameters)."""
    if a.params_id != b.params_id:
        raise IncompatibleDescriptorsError(f"descriptors come from different trained parameters "
                                           f"({a.params_id:#06x} vs {b.params_id:#06x})")
    p = params or MatchParams()
    trained = trained or load_trained()
    g = global_score(a.global_visited, a.global_bits, b.global_visited, b.global_bits, trained.global_weights)
    ia, ib, w = local_matches(a, b, p)
    empty = np.zeros((0, 2), np.float32)
    if len(w) < p.min_matches or w.sum() <= 0:   # (one-way weights are scaled to 0 when no match is two-way)
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    xa, xb = a.xy[ia].astype(np.float64), b.xy[ib].astype(np.float64)
    keep = distrat_inliers(xa, xb, p.distrat_chi2)
    if len(keep) < p.min_inliers:
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    diag = float(np.hypot(*b.proc_size))
    ok = ransac(xa[keep], xb[keep], w[keep], p.geometry, p.ransac_iterations, p.ransac_threshold_frac * diag)
    keep = keep[ok]
    if len(keep) < p.min_inliers:
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    return MatchResult(g, float(w[keep].sum()), len(w), len(keep), a.keypoints[ia[keep]], b.keypoints[ib[keep]],
                       w[keep])
