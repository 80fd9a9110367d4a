"""k-means++ seeding and Lloyd iterations for one node of the vocabulary tree, for either descriptor kind."""
from __future__ import annotations

import numpy as np

from .kinds import DescriptorKind, centres, distances, unpacked_bits


def kmeanspp_seeds(kind: DescriptorKind, x: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of up to k seeds (Arthur & Vassilvitskii): each new seed is drawn with probability proportional to
    its squared distance to the nearest seed so far. Fewer than k come back when the remaining points all coincide
    with seeds."""
    n = len(x)
    first = int(rng.integers(n))
    seeds = [first]
    d2 = distances(kind, x, x[first:first + 1])[:, 0].astype(np.float64) ** 2
    while len(seeds) < min(k, n):
        total = d2.sum()
        if total <= 0:
            break
        idx = int(np.searchsorted(np.cumsum(d2), rng.random() * total, side="right"))
        idx = min(idx, n - 1)
        seeds.append(idx)
        d2 = np.minimum(d2, distances(kind, x, x[idx:idx + 1])[:, 0].astype(np.float64) ** 2)
    return np.asarray(seeds, np.int64)


def kmeans(kind: DescriptorKind, x: np.ndarray, k: int, rng: np.random.Generator,
           iters: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Cluster the rows of x into at most k groups. Returns (labels (n,), centres (m, D)) with m <= k non-empty
    clusters and labels = nearest centre, so the training assignment agrees with how queries descend the tree."""
    c = x[kmeanspp_seeds(kind, x, k, rng)].copy()
    bits = unpacked_bits(x) if kind is DescriptorKind.BINARY else None
    labels = np.argmin(distances(kind, x, c), axis=1)
    for _ in range(iters):
        new_c, sizes = centres(kind, x, labels, len(c), bits)
        new_c[sizes == 0] = c[sizes == 0]  # an emptied cluster keeps its old centre
        c = new_c
        new_labels = np.argmin(distances(kind, x, c), axis=1)
        if np.array_equal(new_labels, labels):
            break
        labels = new_labels
    used = np.unique(labels)
    remap = np.full(len(c), -1, np.int64)
    remap[used] = np.arange(len(used))
    return remap[labels], c[used]
