"""k-means++ seeding and Lloyd iterations for many vocabulary-tree nodes at once, for either descriptor kind.

A tree level holds thousands of small nodes; clustering them one by one costs a Python round per node and per
iteration. Here the rows of all the nodes of a level, sorted by node ("group"), are clustered together: every
k-means++ draw and every Lloyd step is one vectorised pass over the rows still in play, whatever the number of
groups, and each group goes through the same k-means++ and Lloyd steps as it would alone (with its own draws).
The paper's k = 8, L = 8 tree of the corridor's 49 000 BRIEF descriptors: 1.1 s CPU, against 1.8 s node by node.
"""
from __future__ import annotations

import numpy as np

from .kinds import (
    DescriptorKind,
    batched_distances,
    centres,
    centres_from_sums,
    cluster_sums,
    distances,
    paired_distances,
    unpacked_bits,
)

_CHUNK_BYTES = 1 << 24  # gathered centres per assignment chunk (16 MB)
_SUMS_BYTES = 1 << 26   # cluster sums kept for incremental centre updates (64 MB)
_FEW_GROUPS = 16        # below this many groups in a chunk, rows are compared group by group


def group_bounds(group: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """Start row and row count of each group; rows must be sorted by group."""
    counts = np.bincount(group, minlength=n_groups).astype(np.int64)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1])).astype(np.int64)
    return starts, counts


def grouped_kmeanspp(kind: DescriptorKind, x: np.ndarray, group: np.ndarray, n_groups: int, k: int,
                     u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """k-means++ seeds (Arthur & Vassilvitskii) of every group: the first seed uniformly, each next one with
    probability proportional to its squared distance to the nearest seed so far. `u` (n_groups, k) are the uniform
    draws. Returns (seeds (n_groups, k) row indices, valid (n_groups, k)); a group stops early (invalid slots) when
    its remaining rows all coincide with seeds, e.g. a group of fewer than k distinct rows gets exactly those."""
    starts, counts = group_bounds(group, n_groups)
    ends = starts + counts - 1
    seeds = np.zeros((n_groups, k), np.int64)
    valid = np.zeros((n_groups, k), bool)
    has = counts > 0
    seeds[:, 0] = np.where(has, starts + np.minimum((u[:, 0] * counts).astype(np.int64), counts - 1), 0)
    valid[:, 0] = has
    d2 = paired_distances(kind, x, x[seeds[group, 0]]).astype(np.float64) ** 2
    for j in range(1, k):
        cs = np.cumsum(d2)
        before = np.where(starts > 0, cs[np.maximum(starts - 1, 0)], 0.0)
        total = np.where(has, cs[np.maximum(ends, 0)] - before, 0.0)
        ok = total > 0
        if not ok.any():
            break
        # first row whose running sum passes the draw: it has d2 > 0, so it is never an existing seed
        pick = np.searchsorted(cs, before + u[:, j] * total, side="right")
        pick = np.clip(pick, starts, np.maximum(ends, 0))
        seeds[:, j] = np.where(ok, pick, 0)
        valid[:, j] = ok
        rows = ok[group]
        d_new = paired_distances(kind, x[rows], x[seeds[group[rows], j]]).astype(np.float64) ** 2
        d2[rows] = np.minimum(d2[rows], d_new)
    return seeds, valid


def assign(kind: DescriptorKind, x: np.ndarray, group: np.ndarray, c: np.ndarray, valid: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest valid centre of each row among its group's centres c (n_groups, k, D) -> (labels, distance to it,
    distance to the second nearest, inf when there is none). Ties go to the lower slot, as in the tree's descent."""
    n, k = len(x), c.shape[1]
    labels = np.empty(n, np.int64)
    best = np.empty(n, np.float64)
    second = np.empty(n, np.float64)
    if n == 0:
        return labels, best, second
    chunk = max(256, _CHUNK_BYTES // max(1, k * c.shape[2] * c.itemsize))
    for s in range(0, n, chunk):
        g = group[s:s + chunk]
        if g[-1] - g[0] < _FEW_GROUPS:
            # few (large) groups: compare each group's rows with its k centres directly (BLAS for floats)
            d = np.empty((len(g), k), np.float32)
            starts = np.searchsorted(g, np.arange(g[0], g[-1] + 2))
            for j, (a, b) in enumerate(zip(starts[:-1], starts[1:])):
                if b > a:
                    d[a:b] = distances(kind, x[s + a:s + b], c[g[0] + j])
        else:
            d = batched_distances(kind, x[s:s + chunk], c[g])
        d[~valid[g]] = np.inf
        lab = np.argmin(d, axis=1)
        at = np.arange(len(lab))
        labels[s:s + chunk] = lab
        best[s:s + chunk] = d[at, lab]
        d[at, lab] = np.inf
        second[s:s + chunk] = d.min(axis=1) if k > 1 else np.inf
    return labels, best, second


def grouped_kmeans(kind: DescriptorKind, x: np.ndarray, group: np.ndarray, n_groups: int, k: int,
                   rng: np.random.Generator, iters: int = 10, restarts: int = 1
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cluster each group's rows (rows sorted by group) into at most k clusters: k-means++ then Lloyd iterations
    until no label changes (or `iters`). With restarts > 1, each group keeps the run of lowest inertia (sum of
    Hamming distances to the majority-bit centres, or of squared Euclidean distances to the means: the quantity
    each kind's centre minimises). Returns (labels (n,) in [0, k), centres (n_groups, k, D), used (n_groups, k));
    labels are the nearest centre, so training rows agree with how queries descend the tree.

    Lloyd iterations skip work that cannot change anything, with the same result as plain Lloyd:
    - only groups where a label changed in the last iteration are updated (the others would not move);
    - cluster sums are updated by the rows that changed cluster (few after the first iterations) when the sums of
      the level fit in memory, else recomputed for the groups still moving;
    - Hamerly's bounds (both distances satisfy the triangle inequality): a row keeps its label without computing
      any distance while an upper bound on the distance to its centre stays below a lower bound on the distance
      to every other centre of its group (bounds moved by how far the centres moved)."""
    bits = unpacked_bits(x) if kind is DescriptorKind.BINARY else None
    width = x.shape[1] * (8 if bits is not None else 1)
    incremental = n_groups * k * width * (4 if bits is not None else 8) <= _SUMS_BYTES
    # float distances carry rounding: a row is only skipped with some margin (binary distances are exact integers)
    margin = 0.0 if bits is not None else 1e-4
    best = None
    for _ in range(restarts):
        seeds, valid = grouped_kmeanspp(kind, x, group, n_groups, k, rng.random((n_groups, k)))
        c = x[seeds]
        labels, upper, lower = assign(kind, x, group, c, valid)
        if incremental:
            sums, sizes = cluster_sums(kind, x, group * k + labels, n_groups * k, bits)
            dirty = np.arange(n_groups * k)                      # cells whose sums changed
        active = np.ones(n_groups, bool)
        for _ in range(iters):
            rows = np.nonzero(active[group])[0]
            gids = np.nonzero(active)[0]
            local = np.cumsum(active)[group[rows]] - 1          # active group -> 0..len(gids)-1
            if incremental:
                # only cells that gained or lost rows move
                flat = c.reshape(n_groups * k, -1)
                moved_c = centres_from_sums(kind, sums[dirty], sizes[dirty], x.dtype)
                keep = sizes[dirty] == 0
                moved_c[keep] = flat[dirty][keep]               # an emptied cluster keeps its old centre
                cell_shift = np.zeros(n_groups * k)
                cell_shift[dirty] = paired_distances(kind, flat[dirty], moved_c)
                flat[dirty] = moved_c
                shift = cell_shift.reshape(n_groups, k)[gids]
                new_c = c[gids]
            else:
                new_c, cell_sizes = centres(kind, x[rows], local * k + labels[rows], len(gids) * k,
                                            None if bits is None else bits[rows])
                new_c = new_c.reshape(len(gids), k, -1)
                old_c = c[gids]
                empty = cell_sizes.reshape(len(gids), k) == 0
                new_c[empty] = old_c[empty]                      # an emptied cluster keeps its old centre
                shift = paired_distances(kind, old_c.reshape(-1, x.shape[1]),
                                         new_c.reshape(-1, x.shape[1])).reshape(len(gids), k).astype(np.float64)
            c[gids] = new_c
            upper[rows] += shift[local, labels[rows]]
            lower[rows] -= shift.max(axis=1)[local]
            check = upper[rows] + margin >= lower[rows]
            cand, cand_local = rows[check], local[check]
            new_labels, new_upper, new_lower = assign(kind, x[cand], cand_local, new_c, valid[gids])
            changed = new_labels != labels[cand]
            moved = cand[changed]
            if incremental and len(moved):
                old_cell, new_cell = group[moved] * k + labels[moved], group[moved] * k + new_labels[changed]
                touched, inv = np.unique(np.concatenate([old_cell, new_cell]), return_inverse=True)
                # rows leave their old cell (-1) and join their new one (+1)
                sign = np.concatenate([-np.ones(len(moved), np.int8), np.ones(len(moved), np.int8)])
                delta, _ = cluster_sums(kind, np.concatenate([x[moved], x[moved]]), inv, len(touched),
                                        None if bits is None else np.concatenate([bits[moved], bits[moved]]),
                                        weights=sign)
                sums[touched] += delta
                np.subtract.at(sizes, old_cell, 1)
                np.add.at(sizes, new_cell, 1)
                dirty = touched
            labels[cand], upper[cand], lower[cand] = new_labels, new_upper, new_lower
            active = np.zeros(n_groups, bool)
            active[group[moved]] = True
            if not active.any():
                break
        if restarts == 1:
            best = [labels, c, valid, None]
            break
        dist = paired_distances(kind, x, c[group, labels]).astype(np.float64)
        inertia = np.bincount(group, weights=dist if bits is not None else dist * dist, minlength=n_groups)
        if best is None:
            best = [labels, c, valid, inertia]
            continue
        better = inertia < best[3]
        rows = better[group]
        best[0][rows] = labels[rows]
        best[1][better] = c[better]
        best[2][better] = valid[better]
        best[3][better] = inertia[better]
    labels, c, valid, _ = best
    used = np.zeros((n_groups, k), bool)
    used[group, labels] = True
    return labels, c, used


def kmeans(kind: DescriptorKind, x: np.ndarray, k: int, rng: np.random.Generator, iters: int = 10,
           restarts: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Cluster the rows of x into at most k groups. Returns (labels (n,), centres (m, D)) with m <= k non-empty
    clusters, labels = index of the nearest centre."""
    labels, c, used = grouped_kmeans(kind, x, np.zeros(len(x), np.int64), 1, k, rng, iters, restarts)
    remap = np.cumsum(used[0]) - 1
    return remap[labels], c[0][used[0]]


def kmeanspp_seeds(kind: DescriptorKind, x: np.ndarray, k: int, rng: np.random.Generator) -> np.ndarray:
    """Row indices of up to k k-means++ seeds of x (fewer when the rows have fewer than k distinct values)."""
    seeds, valid = grouped_kmeanspp(kind, x, np.zeros(len(x), np.int64), 1, k, rng.random((1, k)))
    return seeds[0][valid[0]]
