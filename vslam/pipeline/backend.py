"""Accumulate keyframe nodes, odometry and loop edges, and hand them to the `graph` package to optimise."""
from __future__ import annotations

import numpy as np

from graph.incremental import IncrementalPoseGraph
from graph.model import PoseGraphData
from graph.params import GraphParams, InitMethod
from graph.pose_graph import PoseGraph
from graph.result import GraphResult


def _floored(cov: np.ndarray) -> np.ndarray:
    # a floor keeps a degenerate covariance (e.g. an exactly repeated fallback) invertible
    return np.asarray(cov, float) + np.eye(3) * 1e-12


class PoseGraphBuilder:
    """Planar pose graph over keyframes (node id = frame index), solved in batch (graph.PoseGraph)."""

    incremental = False

    def __init__(self, params: GraphParams):
        self.graph = PoseGraph(2, params)

    def add_node(self, frame: int, guess: np.ndarray) -> None:
        self.graph.add_node(int(frame), guess)

    def set_guesses(self, poses: np.ndarray) -> None:
        self.graph.set_guesses(poses)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray) -> None:
        self.graph.add_odometry(int(i), int(j), delta, _floored(cov))

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray, probability: float | None) -> int:
        """Loop from node i (the earlier keyframe) to node j; returns its index among the loops."""
        p = 1.0 if probability is None or not np.isfinite(probability) else float(probability)
        return self.graph.add_loop(int(i), int(j), delta, _floored(cov), probability=p)

    def data(self) -> PoseGraphData:
        return self.graph.to_data()

    def optimize(self, warm_start: bool = False) -> GraphResult:
        """Batch solve. warm_start: begin from the current guesses (the previous solution + odometry)."""
        return self.graph.optimize(init=InitMethod.GIVEN if warm_start else None)


class IncrementalBuilder:
    """The same interface over iSAM2 (graph.IncrementalPoseGraph): loops are gated and inserted as they come,
    and the current estimate is read after each update."""

    incremental = True

    def __init__(self, params: GraphParams):
        # loops reach the graph already verified (geometry + P(loop) threshold), and a run may close only a few:
        # use those that fit the stated model at once instead of waiting for the gate's 20-loop warm-up
        self.graph = IncrementalPoseGraph(2, params.replace(gate_warmup_stated=True))
        self.n_loops = 0

    def add_node(self, frame: int, guess: np.ndarray) -> None:
        self.graph.add_node(int(frame), guess)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray) -> None:
        self.graph.add_odometry(int(i), int(j), delta, _floored(cov))

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray, probability: float | None) -> int:
        p = None if probability is None or not np.isfinite(probability) else float(probability)
        self.n_loops += 1
        return self.graph.add_loop(int(i), int(j), delta, _floored(cov), probability=p)

    def update(self) -> tuple[np.ndarray, np.ndarray]:
        """Insert what is pending; (node ids, poses) of the current estimate."""
        self.graph.update()
        return self.graph.estimate()

    def loop_inliers(self) -> np.ndarray:
        return self.graph.loop_inliers()

    def data(self) -> PoseGraphData:
        return self.graph.to_data()

    def optimize(self, warm_start: bool = False) -> GraphResult:
        """Final: flush, classify every loop, a few more updates; the GraphResult."""
        return self.graph.result(classify=True)
