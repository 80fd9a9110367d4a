"""Connected components of a pose graph, and one anchor per component.

A component that no edge links to the anchored one has no measured relation to it: its placement is a free gauge,
and without a prior of its own the solver moves it wherever the initial guess put it (the odometry tree starts it
at the identity, LAGO / chordal fail on it outright). So the optimize path holds each such component at the given
pose of its first node (file order), with the same tight prior as the graph's own anchor, and says so.
"""
from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from graph.ids import id_array
from graph.model import PoseGraphData


class DisconnectedGraphWarning(UserWarning):
    """The graph has more than one connected component: each is anchored separately."""


def component_labels(data: PoseGraphData, odometry_only: bool = False) -> np.ndarray:
    """(N,) component index of each node (over odometry edges only if asked); components are numbered in the
    order of their first node."""
    n = data.num_nodes
    if n == 0:
        return np.zeros(0, np.int64)
    a, b = data.edge_index_pairs()
    if odometry_only:
        a, b = a[~data.is_loop], b[~data.is_loop]
    adj = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    _, raw = connected_components(adj, directed=False)
    # renumber by first appearance in node order, so component 0 holds node 0 (the default anchor)
    _, first = np.unique(raw, return_index=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first)] = np.arange(len(first))
    return rank[raw]


def component_sizes(labels: np.ndarray) -> np.ndarray:
    return np.bincount(labels) if len(labels) else np.zeros(0, np.int64)


def anchor_components(data: PoseGraphData, warn: bool = True) -> tuple[PoseGraphData, list[str]]:
    """`data` with one anchored node in every component: the file's FIX vertices, plus the first node of each
    component none of them is in. Returns (data, notes); `data` itself when the graph is connected."""
    labels = component_labels(data)
    sizes = component_sizes(labels)
    if len(sizes) <= 1:
        return data, []
    fixed_pos = data.index_of(data.fixed) if len(data.fixed) else np.zeros(1, np.int64)   # default anchor: node 0
    anchored = set(labels[fixed_pos].tolist())
    first = np.array([int(np.flatnonzero(labels == c)[0]) for c in range(len(sizes))])
    new = [int(first[c]) for c in range(len(sizes)) if c not in anchored]
    # keep the graph's own anchor explicit: once `fixed` is non-empty it replaces the implicit node-0 anchor
    keep = data.fixed.tolist() if len(data.fixed) else [data.node_ids[0]]
    out = replace(data, fixed=id_array(keep + [data.node_ids[k] for k in new]))
    shown = ", ".join(str(int(s)) for s in sizes[:10]) + (", ..." if len(sizes) > 10 else "")
    note = (f"the graph has {len(sizes)} disconnected components (sizes {shown} nodes): no edge relates them, "
            f"so each is held at the given pose of its first node ({len(new)} extra anchor(s))")
    if warn:
        warnings.warn(DisconnectedGraphWarning(note), stacklevel=3)
    return out, [note]


def loops_join_odometry_parts(data: PoseGraphData) -> bool:
    """True when some loop is the only link between two parts of the odometry chain (ETHCampus: no odometry edge
    between vertices 1431 and 1432). The gated pass tests each loop against an estimate propagated along odometry,
    which does not exist across such a gap: it defers the joining loops and the far part floats."""
    if not data.num_loops:
        return False
    return int(component_labels(data, odometry_only=True).max()) > int(component_labels(data).max())
