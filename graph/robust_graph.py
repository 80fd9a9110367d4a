"""`RobustPoseGraph`: the one front door of the back end for building a graph and solving it, in batch or online.

    from graph import RobustPoseGraph, GraphParams
    g = RobustPoseGraph(dim=2, params=GraphParams.preset("default"))        # strategy from params.solver.method
    g.add_node(0, [0, 0, 0]); g.add_node(1)
    g.add_odometry(0, 1, delta, cov)
    k = g.add_loop(1, 0, delta, cov, probability=0.9)
    ids, poses = g.update()          # batch: a robust solve of what is there; iSAM2: insert what is pending
    ids, poses = g.estimate()        # the latest estimate, without solving
    res = g.result()                 # final GraphResult: every loop classified
    RobustPoseGraph.solve(data)      # a whole PoseGraphData (files) in one call; the same as graph.optimize

The solver is a strategy object (graph.optimizer): `BatchStrategy` (`Solver.LM`) or `IncrementalStrategy`
(`Solver.ISAM2`), chosen by `params.solver.method` or the `strategy` argument. The robust method is the batch
solve's `LoopRejector` (graph.rejection), chosen by `params.robust.method`. Both strategies keep the graph in the
same `PoseGraphData` form, so `to_data()` and `write_g2o` work either way.
"""
from __future__ import annotations

import os

import numpy as np

from graph.model import PoseGraphData
from graph.optimizer import GraphStrategy, optimize, strategy_class
from graph.params import GraphParams, Solver
from graph.result import GraphResult, write_g2o


class RobustPoseGraph:
    """Nodes, odometry and loop closures in; estimates and loop labels out. See the module docstring."""

    def __init__(self, dim: int = 2, params: GraphParams | None = None, strategy: Solver | str | None = None):
        self.params = (params or GraphParams()).replace(**({"solver": strategy} if strategy is not None else {}))
        self.dim = dim
        self.strategy: GraphStrategy = strategy_class(self.params)(dim, self.params)

    @property
    def incremental(self) -> bool:
        """True for the online (iSAM2) strategy: `update()` is cheap and meant to be called as data arrives."""
        return self.strategy.online

    @classmethod
    def solve(cls, data: PoseGraphData, params: GraphParams | None = None) -> GraphResult:
        """Optimise a whole graph (e.g. read from a file) with `params` (strategy = params.solver.method)."""
        return optimize(data, params)

    # ------------------------------------------------------------------------------------------------ building
    def add_node(self, node_id: int, guess: np.ndarray | None = None) -> None:
        """A new pose; without a guess it is placed by odometry."""
        self.strategy.add_node(node_id, guess)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                     information: np.ndarray | None = None) -> None:
        """Odometry i -> j (trusted): delta = x_i^-1 x_j; cov or information in (x, y, theta) (3D: x y z rx ry rz)."""
        self.strategy.add_odometry(i, j, delta, cov, information)

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                 probability: float | None = None, information: np.ndarray | None = None) -> int:
        """Loop closure i -> j with P(loop) (None or NaN: unknown); returns its loop index (order added)."""
        p = None if probability is None or not np.isfinite(probability) else float(probability)
        if p is not None and not 0.0 <= p <= 1.0:
            raise ValueError(f"loop probability must be in [0, 1], got {p}")
        return self.strategy.add_loop(i, j, delta, cov, p, information)

    def set_guesses(self, poses: np.ndarray) -> None:
        """Initial guesses of every node, in the order added (batch: the start of a warm-started solve; iSAM2
        keeps its own estimate and ignores them)."""
        self.strategy.set_guesses(poses)

    # ------------------------------------------------------------------------------------------------- solving
    def update(self) -> tuple[np.ndarray, np.ndarray]:
        """Bring the estimate up to date: iSAM2 inserts what is pending; batch solves the graph robustly."""
        return self.strategy.update()

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """(node ids, poses) of the latest estimate; before any solve, the nodes' guesses."""
        return self.strategy.estimate()

    def loop_inliers(self) -> np.ndarray:
        """Current inlier flag of each loop: the last `result()` while no loop was added since; else iSAM2's online
        gate and kernel (batch: every loop until the first solve, then the last labels)."""
        return self.strategy.loop_inliers()

    def result(self, warm_start: bool = False) -> GraphResult:
        """The final solve: every loop classified. warm_start (batch): start from the current guesses."""
        return self.strategy.result(warm_start)

    def to_data(self) -> PoseGraphData:
        return self.strategy.to_data()

    def write_g2o(self, path: str | os.PathLike, result: GraphResult | None = None) -> None:
        write_g2o(path, self.to_data(), result)

    @property
    def num_nodes(self) -> int:
        return self.strategy.num_nodes

    @property
    def num_loops(self) -> int:
        return self.strategy.num_loops
