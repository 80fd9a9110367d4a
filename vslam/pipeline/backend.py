"""Accumulate keyframe nodes, odometry and loop edges, and hand them to the `graph` package to optimise."""
from __future__ import annotations

import numpy as np

from graph.batch import optimize
from graph.incremental import IncrementalPoseGraph
from graph.model import PoseGraphData
from graph.params import GraphParams, InitMethod
from graph.result import GraphResult


def _information(cov: np.ndarray) -> np.ndarray:
    c = 0.5 * (np.asarray(cov, float) + np.asarray(cov, float).T)
    # a floor keeps a degenerate covariance (e.g. an exactly repeated fallback) invertible
    return np.linalg.inv(c + np.eye(3) * 1e-12)


class PoseGraphBuilder:
    """Planar pose graph over keyframes (node id = frame index), solved in batch."""

    incremental = False

    def __init__(self, params: GraphParams):
        self.params = params
        self.ids: list[int] = []
        self.guess: list[np.ndarray] = []
        self.e_from: list[int] = []
        self.e_to: list[int] = []
        self.z: list[np.ndarray] = []
        self.info: list[np.ndarray] = []
        self.is_loop: list[bool] = []
        self.prob: list[float] = []
        self.n_loops = 0

    def add_node(self, frame: int, guess: np.ndarray) -> None:
        self.ids.append(int(frame))
        self.guess.append(np.asarray(guess, float).copy())

    def set_guesses(self, poses: np.ndarray) -> None:
        self.guess = [np.asarray(p, float).copy() for p in poses]

    def _edge(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray, loop: bool, p: float) -> None:
        self.e_from.append(int(i))
        self.e_to.append(int(j))
        self.z.append(np.asarray(delta, float).copy())
        self.info.append(_information(cov))
        self.is_loop.append(loop)
        self.prob.append(float(p))

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray) -> None:
        self._edge(i, j, delta, cov, False, 1.0)

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray, probability: float | None) -> int:
        """Loop from node i (the earlier keyframe) to node j; returns its index among the loops."""
        self._edge(i, j, delta, cov, True, 1.0 if probability is None or not np.isfinite(probability) else probability)
        self.n_loops += 1
        return self.n_loops - 1

    def data(self) -> PoseGraphData:
        m = len(self.e_from)
        return PoseGraphData(2, np.asarray(self.ids, np.int64), np.asarray(self.guess).reshape(-1, 3),
                             np.asarray(self.e_from, np.int64), np.asarray(self.e_to, np.int64),
                             np.asarray(self.z).reshape(m, 3), np.asarray(self.info).reshape(m, 3, 3),
                             np.asarray(self.is_loop, bool), np.asarray(self.prob, float))

    def optimize(self, warm_start: bool = False) -> GraphResult:
        """Batch solve. warm_start: begin from the current guesses (the previous solution + odometry)."""
        init = InitMethod.GIVEN if warm_start else None
        return optimize(self.data(), self.params, init=init)


class IncrementalBuilder:
    """The same interface over iSAM2 (graph.IncrementalPoseGraph): loops are gated and inserted as they come,
    and the current estimate is read after each update."""

    incremental = True

    def __init__(self, params: GraphParams):
        # loops reach the graph already verified (geometry + P(loop) threshold), and a run may close only a few:
        # use those that fit the stated model at once instead of waiting for the gate's 20-loop warm-up
        self.graph = IncrementalPoseGraph(2, params.with_(gate_warmup_stated=True))
        self.n_loops = 0

    def add_node(self, frame: int, guess: np.ndarray) -> None:
        self.graph.add_node(int(frame), guess)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray) -> None:
        self.graph.add_odometry(int(i), int(j), delta, cov + np.eye(3) * 1e-12)

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray, probability: float | None) -> int:
        p = None if probability is None or not np.isfinite(probability) else float(probability)
        self.n_loops += 1
        return self.graph.add_loop(int(i), int(j), delta, cov + np.eye(3) * 1e-12, probability=p)

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
