"""Seeded false loop closures for robustness experiments, and loop-classification scores."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from graph.model import PoseGraphData


def inject_false_loops(data: PoseGraphData, fraction: float, seed: int,
                       translation_scale: float | None = None) -> tuple[PoseGraphData, np.ndarray]:
    """A copy of `data` with round(fraction * loops) random false loops appended; returns (graph, injected mask).

    Model (perceptual aliasing): two nodes picked uniformly at random, not consecutive, are claimed to be close:
    the relative translation is uniform in [-s, s]^dim with s the 95th percentile of the graph's loop translations
    (at least 1), the rotation uniform (a uniform heading in 2D, a uniform random quaternion in 3D). The information
    matrix is the element-wise median of the true loops' (of the odometry's when there are none), so a false loop
    looks like any other. With no loops in the graph, `fraction` is taken of the odometry edge count.
    Deterministic for a given seed.
    """
    rng = np.random.default_rng(seed)
    n = data.num_nodes
    base = data.num_loops if data.num_loops else data.num_edges
    count = int(round(fraction * base))
    if count == 0 or n < 3:
        return data.copy(), np.zeros(data.num_edges, bool)
    ref = data.is_loop if data.num_loops else ~data.is_loop
    if translation_scale is None:
        t = np.linalg.norm(data.measurements[ref][:, :data.dim], axis=1)
        translation_scale = max(1.0, float(np.percentile(t, 95))) if len(t) else 1.0
    s = translation_scale
    i = rng.integers(0, n, count)
    off = rng.integers(2, n - 1, count)          # |pos_i - pos_j| >= 2 (mod n): never consecutive, never equal
    j = (i + off) % n
    if data.dim == 2:
        z = np.column_stack([rng.uniform(-s, s, (count, 2)), rng.uniform(-np.pi, np.pi, count)])
    else:
        q = rng.normal(size=(count, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        q *= np.where(q[:, 3:4] < 0, -1.0, 1.0)
        z = np.column_stack([rng.uniform(-s, s, (count, 3)), q])
    info = np.median(data.information[ref], axis=0)
    out = data.append_edges(data.node_ids[i], data.node_ids[j], z, np.broadcast_to(info, (count,) + info.shape),
                            True, np.full(count, np.nan))
    injected = np.zeros(out.num_edges, bool)
    injected[data.num_edges:] = True
    return out, injected


@dataclass
class LoopScores:
    """Loop classification against the truth. 'Positive' = a loop the solver kept (labelled inlier)."""

    precision: float          # kept loops that are true / kept loops
    recall: float             # true loops kept / true loops
    false_rejected: float     # injected false loops labelled outlier / injected false loops
    kept: int
    rejected: int


def loop_scores(loop_inlier: np.ndarray, loop_is_false: np.ndarray) -> LoopScores:
    inl = np.asarray(loop_inlier, bool)
    bad = np.asarray(loop_is_false, bool)
    kept_true = np.sum(inl & ~bad)
    precision = float(kept_true / inl.sum()) if inl.sum() else 1.0
    recall = float(kept_true / (~bad).sum()) if (~bad).sum() else 1.0
    false_rej = float(np.sum(~inl & bad) / bad.sum()) if bad.sum() else 1.0
    return LoopScores(precision, recall, false_rej, int(inl.sum()), int((~inl).sum()))
