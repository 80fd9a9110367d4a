"""`RobustPoseGraph`: the one front door of the back end for building a graph and solving it, in batch or online.

    from graph import RobustPoseGraph, GraphParams
    g = RobustPoseGraph(dim=2, params=GraphParams.preset("default"))        # strategy from params.solver.method
    g.add_node(0, [0, 0, 0]); g.add_node(1)
    g.add_odometry(0, 1, delta, cov)
    k = g.add_loop(1, 0, delta, cov, probability=0.9)
    ids, poses = g.update()          # batch: a robust solve of what is there; iSAM2: insert what is pending
    ids, poses = g.estimate()        # the latest estimate, without solving
    res = g.result()                 # final GraphResult: every loop classified
    RobustPoseGraph.solve(data)      # a whole PoseGraphData (files) in one call

Strategies: `Solver.LM` (batch Levenberg-Marquardt; robust mode `consensus` by default, graph.robust) and
`Solver.ISAM2` (graph.incremental: loops gated on arrival, classified at the end). Both keep the graph in the same
`PoseGraphData` form, so `to_data()` and `write_g2o` work either way.
"""
from __future__ import annotations

import os

import numpy as np

from graph.incremental import IncrementalPoseGraph
from graph.model import PoseGraphData
from graph.optimizer import optimize
from graph.params import GraphParams, InitMethod, RobustMode, Solver
from graph.pose_graph import PoseGraph
from graph.result import GraphResult, write_g2o


class RobustPoseGraph:
    """Nodes, odometry and loop closures in; estimates and loop labels out. See the module docstring."""

    def __init__(self, dim: int = 2, params: GraphParams | None = None, strategy: Solver | str | None = None):
        self.params = (params or GraphParams()).replace(**({"solver": strategy} if strategy is not None else {}))
        self.dim = dim
        self._batch = PoseGraph(dim, self.params)
        self._inc: IncrementalPoseGraph | None = None
        if self.params.solver.method == Solver.ISAM2:
            inc = self.params
            if inc.robust.method == RobustMode.CONSENSUS:      # the incremental pass classifies with its own GNC
                inc = inc.replace(robust=RobustMode.GNC)
            self._inc = IncrementalPoseGraph(dim, inc)
        self._estimate: tuple[np.ndarray, np.ndarray] | None = None
        self._result: GraphResult | None = None

    @property
    def incremental(self) -> bool:
        return self._inc is not None

    @classmethod
    def solve(cls, data: PoseGraphData, params: GraphParams | None = None) -> GraphResult:
        """Optimise a whole graph (e.g. read from a file) with `params` (strategy = params.solver.method)."""
        return optimize(data, params)

    # ------------------------------------------------------------------------------------------------ building
    def add_node(self, node_id: int, guess: np.ndarray | None = None) -> None:
        self._batch.add_node(node_id, guess)
        if self._inc is not None:
            self._inc.add_node(node_id, guess)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                     information: np.ndarray | None = None) -> None:
        """Odometry i -> j (trusted): delta = x_i^-1 x_j; cov or information in (x, y, theta) (3D: x y z rx ry rz)."""
        self._batch.add_odometry(i, j, delta, cov, information)
        if self._inc is not None:
            self._inc.add_odometry(i, j, delta, cov, information)

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                 probability: float | None = None, information: np.ndarray | None = None) -> int:
        """Loop closure i -> j with P(loop) (None or NaN: unknown); returns its loop index (order added)."""
        p = None if probability is None or not np.isfinite(probability) else float(probability)
        k = self._batch.add_loop(i, j, delta, cov, probability=p, information=information)
        if self._inc is not None:
            self._inc.add_loop(i, j, delta, cov, probability=p, information=information)
        return k

    def set_guesses(self, poses: np.ndarray) -> None:
        """Initial guesses of every node, in the order added (batch: the start of a warm-started solve)."""
        self._batch.set_guesses(poses)

    # ------------------------------------------------------------------------------------------------- solving
    def update(self) -> tuple[np.ndarray, np.ndarray]:
        """Bring the estimate up to date: iSAM2 inserts what is pending; batch solves the graph robustly."""
        if self._inc is not None:
            self._inc.update()
            self._estimate = self._inc.estimate()
        else:
            res = self.result()
            self._estimate = (res.node_ids, res.poses)
        return self._estimate

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """(node ids, poses) of the latest estimate; before any solve, the nodes' guesses."""
        if self._estimate is None:
            data = self._batch.to_data()
            return data.node_ids, data.poses
        return self._estimate

    def loop_inliers(self) -> np.ndarray:
        """Current inlier flag of each loop: the last `result()` while no loop was added since; else iSAM2's online
        gate and kernel (batch: every loop, until the first solve)."""
        if self._result is not None and len(self._result.loop_inlier) == self.num_loops:
            return np.asarray(self._result.loop_inlier, bool)
        if self._inc is not None:
            return self._inc.loop_inliers()
        if self._result is None:
            return np.ones(self._batch.num_loops, bool)
        return np.asarray(self._result.loop_inlier, bool)

    def result(self, warm_start: bool = False) -> GraphResult:
        """The final solve: every loop classified. warm_start (batch): start from the current guesses."""
        if self._inc is not None and self.params.robust.method == RobustMode.CONSENSUS:
            # the final labels come from the batch consensus solve started at the iSAM2 estimate: the online gate
            # tests loops against the drifted estimate at their arrival and rejects true loops under large drift
            online = self._inc.result(classify=False)
            data = self._inc.to_data()
            data.poses = online.poses
            res = optimize(data, self.params.replace(solver={"method": Solver.LM, "init": InitMethod.GIVEN}))
            res.seconds += online.seconds
            res.solver = Solver.ISAM2.value            # the strategy that produced the online estimates
            res.notes.insert(0, f"iSAM2 pass {online.seconds:.3f} s, then the batch consensus solve from it")
        elif self._inc is not None:
            res = self._inc.result(classify=True)
        else:
            data = self._batch.to_data()
            res = optimize(data, self.params.replace(solver={"init": InitMethod.GIVEN}) if warm_start else self.params)
        self._result = res
        self._estimate = (res.node_ids, res.poses)
        return res

    def to_data(self) -> PoseGraphData:
        return self._inc.to_data() if self._inc is not None else self._batch.to_data()

    def write_g2o(self, path: str | os.PathLike, result: GraphResult | None = None) -> None:
        write_g2o(path, self.to_data(), result)

    @property
    def num_nodes(self) -> int:
        return self._batch.num_nodes

    @property
    def num_loops(self) -> int:
        return self._batch.num_loops
