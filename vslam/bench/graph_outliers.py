"""False loop closures as Vertigo's dataset generator makes them (Suenderhauf & Protzel, generateDataset.py).

Policies (the generator's options, re-implemented; counts are a fraction of the graph's true loop count):
- random: two poses drawn uniformly (never equal, never consecutive);
- local: the second pose within 20 poses after the first;
- random-grouped / local-grouped: groups of 10 false loops (i+k, j+k), k = 0..9, all with the same measurement,
  so the members of a group are mutually consistent (what defeats a pairwise-consistency test);
The claimed relative pose says the two poses are close: translation ~ N(0, 0.3) per axis, rotation ~ N(0, 10 deg)
per axis; the information matrix is that of the graph's first loop closure (the generator's default), so a false
loop looks like a true one to a test on the stated noise.
"""
from __future__ import annotations

import numpy as np

from graph.model import PoseGraphData

POLICIES = ("random", "local", "random-grouped", "local-grouped")
GROUP_SIZE = 10
LOCAL_SPAN = 20


def _quat_from_rpy(r, p, y):
    cr, sr, cp, sp, cy, sy = np.cos(r / 2), np.sin(r / 2), np.cos(p / 2), np.sin(p / 2), np.cos(y / 2), np.sin(y / 2)
    w = cr * cp * cy + sr * sp * sy
    x = sr * cp * cy - cr * sp * sy
    yy = cr * sp * cy + sr * cp * sy
    z = cr * cp * sy - sr * sp * cy
    return np.column_stack([x, yy, z, w])


def add_false_loops(data: PoseGraphData, policy: str, fraction: float, seed: int
                    ) -> tuple[PoseGraphData, np.ndarray]:
    """A copy of `data` with round(fraction x true loops) false loops appended (in whole groups for the grouped
    policies); returns (graph, per-loop mask of the false ones, in loop order). Deterministic per seed."""
    if policy not in POLICIES:
        raise ValueError(f"unknown outlier policy {policy!r}; known: {', '.join(POLICIES)}")
    group = GROUP_SIZE if policy.endswith("grouped") else 1
    local = policy.startswith("local")
    n, loops = data.num_nodes, data.num_loops
    groups = int(round(fraction * loops / group))
    if groups == 0:
        return data.copy(), np.zeros(loops, bool)
    rng = np.random.default_rng(seed)
    hi = n - 1 - group
    i_list, j_list, z_list = [], [], []
    for _ in range(groups):
        while True:
            v1 = int(rng.integers(0, hi + 1))
            v2 = int(rng.integers(v1, min(hi, v1 + LOCAL_SPAN) + 1)) if local else int(rng.integers(0, hi + 1))
            v1, v2 = min(v1, v2), max(v1, v2)
            if v2 == v1 + 1:
                v2 = v1 + 2
            if v1 != v2:
                break
        t = rng.normal(0.0, 0.3, data.dim)
        if data.dim == 2:
            z = np.r_[t, rng.normal(0.0, np.radians(10.0))]
        else:
            r, p, y = rng.normal(0.0, np.radians(10.0), 3)
            z = np.r_[t, _quat_from_rpy(np.array([r]), np.array([p]), np.array([y]))[0]]
        for k in range(group):
            i_list.append(v1 + k)
            j_list.append(v2 + k)
            z_list.append(z)
    ref = data.is_loop if loops else ~data.is_loop
    info = data.information[np.flatnonzero(ref)[0]]
    cnt = len(i_list)
    out = data.append_edges(data.node_ids[np.array(i_list)], data.node_ids[np.array(j_list)], np.array(z_list),
                            np.broadcast_to(info, (cnt,) + info.shape), True, np.ones(cnt))
    false = np.zeros(out.num_loops, bool)
    false[loops:] = True
    return out, false
