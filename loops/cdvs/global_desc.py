"""Global descriptor: a binarised VLAD over a small binary codebook (the CDVS SCFV idea on ORB descriptors).

Each ORB descriptor is assigned to its nearest codeword (Hamming); per cluster the bit residuals to the cluster
mean are summed, projected on 32 trained principal directions and binarised by sign. Only "visited" clusters
are sent (a K-bit presence mask + 32 bits each); low modes send only the most populated clusters.

The global score is a weighted correlation: over clusters visited in both images, T[h] (trained weight of a
cluster pair at Hamming distance h, positive when h is typical of the same scene) normalised by sqrt(nA nB).
"""
from __future__ import annotations

import cv2
import numpy as np

from loops.cdvs.trained import GLOBAL_BITS, TrainedParams
from loops.hamming import bit_distances


def assign(desc: np.ndarray, codebook: np.ndarray, knn: int = 1) -> np.ndarray:
    """The `knn` nearest codewords (Hamming) of each descriptor, (N, knn)."""
    if len(desc) == 0:
        return np.zeros((0, knn), dtype=np.int64)
    _, idx = cv2.batchDistance(desc, codebook, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=knn)
    return idx.reshape(-1, knn).astype(np.int64)


MULTI_ASSIGN = 3  # each descriptor votes for its 3 nearest codewords: steadier residual signs with few descriptors


def cluster_signatures(desc: np.ndarray, trained: TrainedParams) -> tuple[np.ndarray, np.ndarray]:
    """ORB descriptors (N, 32) -> (assignment counts (K,), sign bits (K,) uint32 of every visited cluster)."""
    k = trained.n_clusters
    bits = np.zeros(k, dtype=np.uint32)
    if len(desc) == 0:
        return np.zeros(k, dtype=np.int64), bits
    a = assign(desc, trained.codebook, MULTI_ASSIGN).ravel()
    rows = np.repeat(np.arange(len(desc)), MULTI_ASSIGN)
    order = np.argsort(a, kind="stable")
    counts = np.bincount(a, minlength=k)
    present = np.flatnonzero(counts)
    starts = np.concatenate([[0], np.cumsum(counts[present])[:-1]])
    # bit sums per cluster (n_present, 256): unpack the gathered bytes bit-plane-major so the segmented sum runs
    # along contiguous rows (exact integer sums; ~2x faster than a float reduceat over axis 0)
    planes = np.unpackbits(np.ascontiguousarray(desc[rows[order]].T), axis=0)      # (256, 3N) uint8
    sums = np.add.reduceat(planes, starts, axis=1, dtype=np.uint16).T.astype(np.float32)
    resid = sums - counts[present, None] * trained.cluster_mean[present]   # summed residuals
    y = cv2.gemm(resid.astype(np.float32), trained.projection, 1.0, None, 0.0)   # (n_present, 32), OpenCV threads
    weights = (np.uint32(1) << np.arange(GLOBAL_BITS, dtype=np.uint32))
    bits[present] = ((y > 0).astype(np.uint32) * weights).sum(axis=1, dtype=np.uint64).astype(np.uint32)
    return counts, bits


def select_clusters(counts: np.ndarray, bits: np.ndarray, max_clusters: int) -> tuple[np.ndarray, np.ndarray]:
    """Keep at most `max_clusters` visited clusters, most populated first (ties by index: deterministic)."""
    keep = np.flatnonzero(counts > 0)
    if len(keep) > max_clusters:
        keep = keep[np.argsort(-counts[keep], kind="stable")[:max_clusters]]
    visited = np.zeros(len(counts), dtype=bool)
    visited[keep] = True
    return visited, np.where(visited, bits, np.uint32(0)).astype(np.uint32)


def aggregate(desc: np.ndarray, trained: TrainedParams, max_clusters: int) -> tuple[np.ndarray, np.ndarray]:
    """ORB descriptors (N, 32) -> (visited (K,) bool, bits (K,) uint32, zero where not visited)."""
    return select_clusters(*cluster_signatures(desc, trained), max_clusters)


def global_score(vis_a: np.ndarray, bits_a: np.ndarray, vis_b: np.ndarray, bits_b: np.ndarray,
                 weights: np.ndarray) -> float:
    """Weighted correlation of two global descriptors (about 1 for identical images, about 0 for unrelated)."""
    na, nb = int(vis_a.sum()), int(vis_b.sum())
    if na == 0 or nb == 0:
        return 0.0
    common = vis_a & vis_b
    h = bit_distances(bits_a[common], bits_b[common])
    return float(weights[h].sum() / np.sqrt(na * nb))


ABSENT = np.uint8(64)  # added to a Hamming distance (0..32) where a cluster is not visited: indexes a zero weight


def absent_marks(visited: np.ndarray) -> np.ndarray:
    """uint8 array, ABSENT where a cluster is not visited, 0 elsewhere (what a database stores per keyframe)."""
    return np.where(visited, np.uint8(0), ABSENT).astype(np.uint8)


def weight_lut(weights: np.ndarray) -> np.ndarray:
    """T[h] as a 256-entry float32 table, zero from ABSENT on (cv2.LUT format)."""
    lut = np.zeros((1, 256), dtype=np.float32)
    lut[0, : len(weights)] = weights
    return lut


def global_scores_many(vis_q: np.ndarray, bits_q: np.ndarray, vis_db: np.ndarray | None, bits_db: np.ndarray,
                       n_db: np.ndarray, weights: np.ndarray, absent_db: np.ndarray | None = None,
                       lut: np.ndarray | None = None) -> np.ndarray:
    """Global scores of one query against M stored descriptors: vis_db (M, K) bool, bits_db (M, K) uint32.

    A database passes `absent_db` = absent_marks(vis_db) (and `lut` = weight_lut(weights)) kept from `add`: the
    scan is then popcount, one OR, one table lookup (cv2.LUT) and a row sum, ~2.5x faster than gather + mask."""
    nq = int(vis_q.sum())
    if nq == 0 or len(bits_db) == 0:
        return np.zeros(len(bits_db))
    h = bit_distances(bits_db, bits_q[None, :])                  # (M, K) uint8 in 0..32
    h |= absent_db if absent_db is not None else absent_marks(vis_db)
    h |= absent_marks(vis_q)[None, :]
    t = cv2.LUT(h, weight_lut(weights) if lut is None else lut)      # T[h], 0 where either side is absent
    s = cv2.reduce(t, 1, cv2.REDUCE_SUM).ravel()
    return s / np.sqrt(np.maximum(n_db, 1) * nq)
