"""Pairwise matching of two compact descriptors: global score, two-way ratio-tested local matches, DISTRAT and a
few RANSAC iterations; the local score is the sum of the match weights of the surviving inliers."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loops.cdvs.codec import Descriptor
from loops.cdvs.geometry import distrat_inliers
from loops.cdvs.global_desc import global_score
from loops.cdvs.params import MatchParams
from loops.cdvs.trained import TrainedParams, load_trained
from loops.errors import LoopsError
from loops.geometry import Predict, ransac_transform, transform_overlap
from loops.hamming import hamming_matrix


class IncompatibleDescriptorsError(LoopsError):
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
    overlap: float = 0.0        # image overlap J implied by the verified transform (0 when nothing was verified);
                                # for a downward camera the floor-footprint overlap of the two views
    transform: Predict | None = None  # the verified transform, processed-image pixels of a -> b (None: none)


def _nearest_two(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per row: index of the nearest column, its distance and the second-nearest distance."""
    return _nearest_two_both(d)[0]


def _nearest_two_both(d: np.ndarray) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray],
                                                 tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Nearest column of each row and nearest row of each column, each with the first and second distances.
    Four passes over the matrix, all along contiguous memory; `d` is modified temporarily and restored."""
    big = np.iinfo(d.dtype).max
    rows, cols = np.arange(d.shape[0]), np.arange(d.shape[1])
    j = d.argmin(axis=1)
    i = d.argmin(axis=0)
    d1r, d1c = d[rows, j], d[i, cols]
    d[rows, j] = big
    d2r = d.min(axis=1)
    d[rows, j] = d1r
    d[i, cols] = big
    d2c = d.min(axis=0)
    d[i, cols] = d1c
    f = np.float64
    return (j, d1r.astype(f), d2r.astype(f)), (i, d1c.astype(f), d2c.astype(f))


def _one_way(j: np.ndarray, d1: np.ndarray, d2: np.ndarray, ratio: float,
             max_d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ok = (d1 <= ratio * d2) & (d1 <= max_d) & (d2 > 0) & (j >= 0)
    i = np.flatnonzero(ok)
    jj = j[i]
    w = np.cos(0.5 * np.pi * np.sqrt(d1[i] / d2[i]))
    # keep, for each matched column, only its best-weighted row (ties: the lowest row)
    o = np.lexsort((-w, jj))
    first = np.ones(len(o), dtype=bool)
    first[1:] = jj[o[1:]] != jj[o[:-1]]
    sel = o[first]
    return i[sel], jj[sel], w[sel]


def local_matches(a: Descriptor, b: Descriptor, p: MatchParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two-way ratio-tested matches (ia, ib, weights), CDVS-style union of both directions: pairs found both
    ways get the mean weight, one-way pairs their own, scaled down when they outnumber the two-way ones."""
    if a.n_local < 2 or b.n_local < 2:
        e = np.zeros(0, dtype=np.int64)
        return e, e, np.zeros(0)
    n_bytes = min(a.local.shape[1], b.local.shape[1])   # priority-ordered bits: compare the common prefix
    hd = hamming_matrix(a.local[:, :n_bytes], b.local[:, :n_bytes])
    max_d = p.max_distance_frac * 8 * n_bytes
    ab, ba = _nearest_two_both(hd)
    i1, j1, w1 = _one_way(*ab, p.ratio, max_d)         # a -> b
    j2, i2, w2 = _one_way(*ba, p.ratio, max_d)         # b -> a
    back = np.full(b.n_local, -1, dtype=np.int64)       # per b feature: its entry in the b -> a list
    back[j2] = np.arange(len(j2))
    k = back[j1]
    mutual = k >= 0
    mutual[mutual] = i2[k[mutual]] == i1[mutual]
    x1 = np.flatnonzero(mutual)
    x2 = k[x1]
    only1 = np.flatnonzero(~mutual)
    in2 = np.zeros(len(j2), dtype=bool)
    in2[x2] = True
    only2 = np.flatnonzero(~in2)
    w_both = 0.5 * (w1[x1] + w2[x2])
    w_one = np.concatenate([w1[only1], w2[only2]])
    if len(w_one) > len(x1) and len(w_one):
        w_one = w_one * (len(x1) / len(w_one))
    ia = np.concatenate([i1[x1], i1[only1], i2[only2]])
    ib = np.concatenate([j1[x1], j1[only1], j2[only2]])
    return ia, ib, np.concatenate([w_both, w_one])


def match(a: Descriptor, b: Descriptor, params: MatchParams | None = None,
          trained: TrainedParams | None = None) -> MatchResult:
    """Compare two descriptors (any modes made with the same trained parameters)."""
    if a.params_id != b.params_id:
        raise IncompatibleDescriptorsError(f"descriptors come from different trained parameters "
                                           f"({a.params_id:#06x} vs {b.params_id:#06x})")
    if a.global_visited.shape != b.global_visited.shape:   # same params id, different K: a forged header
        raise IncompatibleDescriptorsError(f"descriptors have codebooks of different sizes "
                                           f"({a.global_visited.shape[0]} vs {b.global_visited.shape[0]})")
    p = params or MatchParams()
    trained = trained or load_trained()
    g = global_score(a.global_visited, a.global_bits, b.global_visited, b.global_bits, trained.global_weights)
    ia, ib, w = local_matches(a, b, p)
    empty = np.zeros((0, 2), np.float32)
    if len(w) < p.min_matches or w.sum() <= 0:   # (one-way weights are scaled to 0 when no match is two-way)
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    xa, xb = a.xy[ia].astype(np.float64), b.xy[ib].astype(np.float64)
    # the geometric check runs on the best-weighted matches only (DISTRAT is quadratic in their number); the
    # transform it yields then decides for every tentative match
    top = np.argsort(-w, kind="stable")[: p.max_geometry_matches]
    keep = top[distrat_inliers(xa[top], xb[top], p.distrat_chi2)]
    if len(keep) < p.min_inliers:
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    thr = p.ransac_threshold_frac * float(np.hypot(*b.proc_size))
    ok, predict = ransac_transform(xa[keep], xb[keep], w[keep], p.geometry, p.ransac_iterations, thr,
                                   scale_range=p.scale_range, max_anisotropy=p.max_anisotropy)
    if predict is None or ok.sum() < p.min_inliers:
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    inl = ok if len(top) == len(w) else None
    final = keep[ok] if inl is not None else np.flatnonzero(np.sum((predict(xa) - xb) ** 2, axis=1) < thr * thr)
    if len(final) < p.min_inliers:
        return MatchResult(g, 0.0, len(w), 0, empty, empty, np.zeros(0))
    return MatchResult(g, float(w[final].sum()), len(w), len(final), a.keypoints[ia[final]], b.keypoints[ib[final]],
                       w[final], transform_overlap(predict, a.proc_size, b.proc_size), predict)
