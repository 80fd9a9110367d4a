"""`PoseGraph`: a graph built node by node (odometry and loop closures marked explicitly), as `PoseGraphData`.

It is the store of the batch strategy of `RobustPoseGraph` (graph.optimizer) and a builder for files and tests;
it does not solve: `RobustPoseGraph` (or `optimize(g.to_data())`) does."""
from __future__ import annotations

import os

import numpy as np

from graph.formats import read_graph
from graph.model import POSE_WIDTH, TANGENT_DIM, PoseGraphData, checked_edge, information_from
from graph.result import GraphResult, write_g2o


class PoseGraph:
    """A batch pose graph (planar by default). Node ids are arbitrary ints; the first node is the anchor unless
    `anchor()` names others.

        g = PoseGraph()
        g.add_node(0, [0, 0, 0]); g.add_node(1)               # a node without a guess is placed by odometry
        g.add_odometry(0, 1, [1.0, 0.0, 0.1], cov)            # delta = pose 1 in the frame of pose 0
        k = g.add_loop(1, 0, delta, cov, probability=0.97)    # -> loop index k
        res = optimize(g.to_data())                            # GraphResult: poses, res.loop_inlier[k], ...
    """

    def __init__(self, dim: int = 2):
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim}")
        self.dim = dim
        self._ids: list[int] = []
        self._index: dict[int, int] = {}
        self._guess: list[np.ndarray] = []
        self._from: list[int] = []
        self._to: list[int] = []
        self._z: list[np.ndarray] = []
        self._info: list[np.ndarray] = []
        self._loop: list[bool] = []
        self._prob: list[float] = []
        self._fixed: list[int] = []
        self._loop_count = 0

    @classmethod
    def from_data(cls, data: PoseGraphData) -> "PoseGraph":
        g = cls(data.dim)
        for nid, p in zip(data.node_ids.tolist(), data.poses):
            g.add_node(nid, None if np.isnan(p).any() else p)
        for e in range(data.num_edges):
            i, j = int(data.edge_from[e]), int(data.edge_to[e])
            if data.is_loop[e]:
                p = data.probability[e]
                g.add_loop(i, j, data.measurements[e], information=data.information[e],
                           probability=None if np.isnan(p) else float(p))
            else:
                g.add_odometry(i, j, data.measurements[e], information=data.information[e])
        for nid in data.fixed.tolist():
            g.anchor(nid)
        return g

    @classmethod
    def read(cls, path: str | os.PathLike) -> "PoseGraph":
        """A g2o or TORO file; loops are the edges between non-consecutive vertices (see graph.model)."""
        return cls.from_data(read_graph(path))

    # --------------------------------------------------------------------------------------------- building
    def add_node(self, node_id: int, guess: np.ndarray | None = None) -> None:
        node_id = int(node_id)
        if node_id in self._index:
            raise ValueError(f"node {node_id} already exists")
        w = POSE_WIDTH[self.dim]
        g = np.full(w, np.nan) if guess is None else np.asarray(guess, float).reshape(w)
        if guess is not None and not np.all(np.isfinite(g)):
            raise ValueError(f"node {node_id}: guess must be finite")
        self._index[node_id] = len(self._ids)
        self._ids.append(node_id)
        self._guess.append(g)

    def set_guesses(self, poses: np.ndarray) -> None:
        """Replace every node's guess (one row per node, in the order added), e.g. with the previous solution
        before a warm-started solve (init "given")."""
        g = np.asarray(poses, float).reshape(len(self._ids), POSE_WIDTH[self.dim])
        if not np.all(np.isfinite(g)):
            raise ValueError("guesses must be finite")
        self._guess = list(g.copy())

    def anchor(self, node_id: int) -> None:
        """Hold this node at its guess (identity without one); by default the first node is the anchor."""
        if int(node_id) not in self._index:
            raise KeyError(f"unknown node id {int(node_id)}")
        if int(node_id) not in self._fixed:
            self._fixed.append(int(node_id))

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                     information: np.ndarray | None = None) -> int:
        """Odometry i -> j (trusted); cov or information in (x, y, theta) order (3D: x y z rx ry rz).
        Returns the edge index."""
        return self._add(i, j, delta, cov, information, False, float("nan"))

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                 probability: float | None = None, information: np.ndarray | None = None) -> int:
        """Loop closure i -> j from geometric verification, with P(loop) from the loop model (None: unknown).
        Returns the loop index (0, 1, ... in the order added)."""
        p = float("nan") if probability is None else float(probability)
        if not (np.isnan(p) or 0.0 <= p <= 1.0):
            raise ValueError(f"loop probability must be in [0, 1], got {p}")
        self._add(i, j, delta, cov, information, True, p)
        self._loop_count += 1
        return self._loop_count - 1

    def _add(self, i, j, delta, cov, information, is_loop, p) -> int:
        i, j, z = checked_edge(i, j, delta, self._index, self.dim)
        self._from.append(i)
        self._to.append(j)
        self._z.append(z)
        self._info.append(information_from(cov, information, TANGENT_DIM[self.dim]))
        self._loop.append(is_loop)
        self._prob.append(p)
        return len(self._from) - 1

    @property
    def num_nodes(self) -> int:
        return len(self._ids)

    @property
    def num_loops(self) -> int:
        return self._loop_count

    def to_data(self) -> PoseGraphData:
        w, d = POSE_WIDTH[self.dim], TANGENT_DIM[self.dim]
        lp = np.asarray(self._loop, bool)
        return PoseGraphData(self.dim, np.asarray(self._ids, np.int64), np.asarray(self._guess).reshape(-1, w),
                             self._from, self._to, np.asarray(self._z).reshape(-1, w),
                             np.asarray(self._info).reshape(-1, d, d), lp,
                             np.where(lp, np.asarray(self._prob, float), 1.0), np.asarray(self._fixed, np.int64))

    def write_g2o(self, path: str | os.PathLike, result: GraphResult | None = None) -> None:
        """The graph as g2o (TORO for *.graph), vertices at the result's poses when given."""
        write_g2o(path, self.to_data(), result)
