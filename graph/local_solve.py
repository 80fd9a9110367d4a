"""A least-squares solve over a neighbourhood of the map, every other pose held where it is.

Why: a loop between nodes a few steps apart (graph.thresholds.short_span) moves only the odometry between its ends
and their neighbourhood; the rest of a densely looped map is held by its own loops. Re-solving the whole graph to
offer such a loop back (the short-tail screen, graph.robust) costs a full factorisation per offer (w10000 at 50 %
local: 179 solves of ~0.3 s), while the poses it can move are a few dozen. The solve here holds every node
outside `free` at its value (gtsam.NonlinearEquality) and keeps only the factors touching a free node, so its
cost is that of the neighbourhood.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.batch import BuiltGraph, solve_lm
from graph.factors import graph_of
from graph.params import GraphParams

__all__ = ["local_solve", "neighbourhood"]


def neighbourhood(num_nodes: int, a: np.ndarray, b: np.ndarray, window: int) -> np.ndarray:
    """Mask over nodes: every node within `window` steps of the stretch [min(a, b), max(a, b)] of each loop with
    ends (a, b) (node indices)."""
    lo = np.maximum(np.minimum(a, b) - window, 0)
    hi = np.minimum(np.maximum(a, b) + window, num_nodes - 1)
    # mark the stretches by a difference array: +1 at each start, -1 past each end
    d = np.zeros(num_nodes + 1, np.int64)
    np.add.at(d, lo, 1)
    np.add.at(d, hi + 1, -1)
    return np.cumsum(d[:-1]) > 0


def local_solve(built: BuiltGraph, keep: np.ndarray, values: gtsam.Values, free: np.ndarray, dim: int,
                params: GraphParams, max_iterations: int | None = None) -> tuple[gtsam.Values, int]:
    """LM over the nodes selected by `free` (mask over nodes) with the anchors, the odometry and the loops of
    `keep` (mask over `built.loops`) that touch a free node; every other node those factors touch is held at
    `values`. Returns (a copy of `values` with the free nodes updated, LM iterations)."""
    a, b = built.a, built.b
    odo = built.odo_idx
    touch_odo = free[a[odo]] | free[b[odo]]
    li = built.loop_idx
    touch_loop = np.asarray(keep, bool) & (free[a[li]] | free[b[li]])
    factors = [f for f, t in zip(built.odometry, touch_odo.tolist()) if t]
    factors += [built.loops[i] for i in np.flatnonzero(touch_loop).tolist()]
    factors += [f for f, n in zip(built.priors, np.asarray(built.anchors, np.int64).tolist()) if free[n]]
    ends = np.concatenate([a[odo[touch_odo]], b[odo[touch_odo]], a[li[touch_loop]], b[li[touch_loop]]])
    nodes = np.unique(np.concatenate([ends, np.flatnonzero(free)]))
    g = graph_of(factors)
    v0 = gtsam.Values()
    equality = gtsam.NonlinearEqualityPose2 if dim == 2 else gtsam.NonlinearEqualityPose3
    at = values.atPose2 if dim == 2 else values.atPose3
    for n in nodes.tolist():
        pose = at(n)
        v0.insert(n, pose)
        if not free[n]:
            g.add(equality(n, pose))
    v, it = solve_lm(g, v0, params, max_iterations)
    out = gtsam.Values(values)
    get = v.atPose2 if dim == 2 else v.atPose3
    for n in np.flatnonzero(free).tolist():
        out.update(n, get(n))
    return out, it
