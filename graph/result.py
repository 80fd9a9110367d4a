"""The outcome of an optimisation, and writers for it (TUM trajectory, g2o / TORO graph)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from graph.formats import write_graph
from graph.model import PoseGraphData
from odometry.shared.tum import write_tum as _write_tum


@dataclass
class GraphResult:
    dim: int
    node_ids: np.ndarray          # (N,) in the graph's node order
    poses: np.ndarray             # (N, 3) x y theta, or (N, 7) x y z qx qy qz qw
    loop_edges: np.ndarray        # (L,) edge indices of the loops; loop k of the API is row k
    loop_inlier: np.ndarray       # (L,) bool
    loop_weight: np.ndarray       # (L,) in [0, 1]: GNC weight, M-estimator weight, or 1
    loop_residual: np.ndarray     # (L,) squared Mahalanobis residual r^2 at the solution (unweighted)
    initial_cost: float           # objective at the initial guess (gtsam error: 0.5 * sum of r^2)
    final_cost: float             # objective at the solution (for GNC: the weighted graph, rejected loops off)
    iterations: int               # LM iterations in total (iSAM2: number of updates)
    seconds: float                # wall time of the solve, initial guess included
    init_seconds: float = 0.0     # of which the initial guess
    solver: str = "lm"
    robust: str = "gnc"
    init: str = ""
    gnc_iterations: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def loops_kept(self) -> int:
        return int(self.loop_inlier.sum())

    @property
    def loops_rejected(self) -> int:
        return int(len(self.loop_inlier) - self.loop_inlier.sum())

    def pose(self, node_id: int) -> np.ndarray:
        k = np.flatnonzero(self.node_ids == node_id)
        if len(k) == 0:
            raise KeyError(f"unknown node id {node_id}")
        return self.poses[k[0]].copy()

    def write_tum(self, path: str | os.PathLike, timestamps: np.ndarray | None = None) -> None:
        """The optimised trajectory in TUM format (timestamps default to the node ids)."""
        write_tum(path, self, timestamps)

    def write_g2o(self, path: str | os.PathLike, data: PoseGraphData) -> None:
        """`data` (the graph this result solves) with the optimised vertices; TORO for *.graph."""
        write_g2o(path, data, self)

    def summary(self) -> str:
        return (f"{len(self.node_ids)} nodes, solver {self.solver}, robust {self.robust}, init {self.init}: "
                f"cost {self.initial_cost:.6g} -> {self.final_cost:.6g}, {self.iterations} iterations"
                f"{f' ({self.gnc_iterations} GNC steps)' if self.gnc_iterations else ''}, {self.seconds:.3f} s; "
                f"loops kept {self.loops_kept} / rejected {self.loops_rejected}")


def write_tum(path: str | os.PathLike, result: GraphResult, timestamps: np.ndarray | None = None) -> None:
    """The optimised trajectory in TUM format; timestamps default to the node ids."""
    t = result.node_ids.astype(float) if timestamps is None else np.asarray(timestamps, float)
    _write_tum(path, t, result.poses)


def write_g2o(path: str | os.PathLike, data: PoseGraphData, result: GraphResult | None = None) -> None:
    """The graph with optimised vertices (ids, edge order, information and comments as read); TORO for *.graph."""
    if result is not None and not np.array_equal(result.node_ids, data.node_ids):
        raise ValueError("result does not belong to this graph (node ids differ)")
    write_graph(path, data, None if result is None else result.poses)
