"""The solver strategies of `RobustPoseGraph` (batch Levenberg-Marquardt, iSAM2) and `optimize(data, params)`, the
whole-graph solve behind `RobustPoseGraph.solve` and `vslam graph optimize`.

A strategy holds the graph while it is built (`add_node`, `add_odometry`, `add_loop`), brings the estimate up to
date (`update`), and makes the final solve (`result`); its class method `solve(data, params)` does the same for a
whole `PoseGraphData` (a file). Robust handling of loops is not the strategy's business: batch solves ask
`graph.rejection.loop_rejector` for the robust method; iSAM2 protects loops online (gate and kernel,
graph.incremental) and classifies them at the end.
"""
from __future__ import annotations

import time
from abc import ABC, abstractmethod

import numpy as np

from graph.components import anchor_components
from graph.errors import GraphError
from graph.incremental import IncrementalPoseGraph, full_pass, replay
from graph.linear import solver_scope
from graph.model import PoseGraphData
from graph.params import GraphParams, InitMethod, RobustMode, Solver
from graph.pose_graph import PoseGraph
from graph.rejection import loop_rejector
from graph.result import GraphResult


def optimize(data: PoseGraphData, params: GraphParams | None = None, *, solver: Solver | str | None = None,
             robust: RobustMode | str | None = None, init: InitMethod | str | None = None) -> GraphResult:
    """Optimise a pose graph; keyword arguments override `params.solver.method`, `.robust.method`, `.solver.init`.

    Every component of the graph is anchored (graph.components: a warning names them when there is more than one).
    Should gtsam still fail (an indeterminate system, a key it cannot find), the graph is solved once more from the
    odometry tree with batch LM and no gate; a second failure is a GraphError naming the cause, never gtsam's.
    """
    solver_over = {k: v for k, v in (("method", solver), ("init", init)) if v is not None}
    over = {k: v for k, v in (("solver", solver_over or None), ("robust", robust)) if v is not None}
    params = (params or GraphParams()).replace(**over)
    if data.num_nodes == 0:
        raise GraphError("the pose graph has no nodes")
    data, notes = anchor_components(data)
    try:
        res = strategy_class(params).solve(data, params)
    except GraphError:
        raise
    except (RuntimeError, IndexError, ValueError) as exc:
        plain = params.replace(solver={"method": Solver.LM, "init": InitMethod.ODOMETRY},
                               robust={"gate_loops": False})
        try:
            res = BatchStrategy.solve(data, plain)
        except GraphError:
            raise
        except (RuntimeError, IndexError, ValueError) as exc2:
            raise GraphError(f"the solver failed on this graph: {_first_line(exc2)} (first attempt: "
                             f"{_first_line(exc)})") from exc2
        res.notes.insert(0, f"solved from the odometry tree with batch LM after: {_first_line(exc)}")
    res.notes[:0] = notes
    return res


def _first_line(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return f"{type(exc).__name__}: {' '.join(lines[:2])}" if lines else type(exc).__name__


class GraphStrategy(ABC):
    """How a `RobustPoseGraph` solves: one graph store, one update rule, one final solve."""

    online = False                  # True: update() is cheap and meant to be called as data arrives

    def __init__(self, dim: int, params: GraphParams):
        self.dim = dim
        self.params = params
        self._result: GraphResult | None = None
        self._estimate: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    @abstractmethod
    def solve(cls, data: PoseGraphData, params: GraphParams) -> GraphResult:
        """A whole graph in one call (no anchoring of components nor failure fallback: see `optimize`)."""

    @abstractmethod
    def add_node(self, node_id: int, guess: np.ndarray | None) -> None: ...

    @abstractmethod
    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None,
                     information: np.ndarray | None) -> None: ...

    @abstractmethod
    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None, probability: float | None,
                 information: np.ndarray | None) -> int: ...

    @abstractmethod
    def set_guesses(self, poses: np.ndarray) -> None: ...

    @abstractmethod
    def update(self) -> tuple[np.ndarray, np.ndarray]: ...

    @abstractmethod
    def final(self, warm_start: bool) -> GraphResult: ...

    @abstractmethod
    def to_data(self) -> PoseGraphData: ...

    @abstractmethod
    def online_inliers(self) -> np.ndarray:
        """Inlier flag of each loop when no final result covers them all."""

    @property
    @abstractmethod
    def num_nodes(self) -> int: ...

    @property
    @abstractmethod
    def num_loops(self) -> int: ...

    def result(self, warm_start: bool = False) -> GraphResult:
        """The final solve (every loop classified); kept as the latest estimate and labels."""
        res = self.final(warm_start)
        self._result = res
        self._estimate = (res.node_ids, res.poses)
        return res

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """(node ids, poses) of the latest estimate; before any solve, the nodes' guesses."""
        if self._estimate is None:
            data = self.to_data()
            return data.node_ids, data.poses
        return self._estimate

    def loop_inliers(self) -> np.ndarray:
        """The last result's labels while no loop was added since; else the strategy's online labels."""
        if self._result is not None and len(self._result.loop_inlier) == self.num_loops:
            return np.asarray(self._result.loop_inlier, bool)
        return self.online_inliers()


class BatchStrategy(GraphStrategy):
    """Batch Levenberg-Marquardt: the graph is stored as added; every update is a robust solve of all of it."""

    def __init__(self, dim: int, params: GraphParams):
        super().__init__(dim, params)
        self._graph = PoseGraph(dim)

    @classmethod
    def solve(cls, data: PoseGraphData, params: GraphParams) -> GraphResult:
        # every LM call of the solve picks direct Cholesky or PCG from its fill-in (graph.linear)
        a, b = data.edge_index_pairs()
        with solver_scope(np.column_stack([a, b]), data.dim, params) as scope:
            res = loop_rejector(data, params).solve(data, params)
        if scope.iterative_calls:
            res.notes.append(f"linear solver: PCG in {scope.iterative_calls} LM calls whose direct factorisation "
                             f"was estimated above {params.solver.direct_max_cost:.3g} flops")
        return res

    def add_node(self, node_id: int, guess: np.ndarray | None) -> None:
        self._graph.add_node(node_id, guess)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None,
                     information: np.ndarray | None) -> None:
        self._graph.add_odometry(i, j, delta, cov, information)

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None, probability: float | None,
                 information: np.ndarray | None) -> int:
        return self._graph.add_loop(i, j, delta, cov, probability=probability, information=information)

    def set_guesses(self, poses: np.ndarray) -> None:
        self._graph.set_guesses(poses)

    def update(self) -> tuple[np.ndarray, np.ndarray]:
        res = self.result()
        return res.node_ids, res.poses

    def final(self, warm_start: bool) -> GraphResult:
        params = self.params.replace(solver={"init": InitMethod.GIVEN}) if warm_start else self.params
        return optimize(self._graph.to_data(), params)

    def to_data(self) -> PoseGraphData:
        return self._graph.to_data()

    def online_inliers(self) -> np.ndarray:
        # before the first solve every loop counts; after it, the last labels (loops added since are not solved)
        if self._result is None:
            return np.ones(self.num_loops, bool)
        return np.asarray(self._result.loop_inlier, bool)

    @property
    def num_nodes(self) -> int:
        return self._graph.num_nodes

    @property
    def num_loops(self) -> int:
        return self._graph.num_loops


class IncrementalStrategy(GraphStrategy):
    """iSAM2: nodes and factors are inserted as they arrive (loops gated on arrival and behind a kernel), so the
    online estimate is cheap and protected from false loops; the final solve classifies every loop.

    With robust method `consensus` (the default) the iSAM2 pass protects the online estimate with its gate and GNC,
    and the final labels and poses are the batch `LoopRejector`'s on everything added, with the batch parameters:
    the same decision as the batch strategy on the same graph (the online gate tests loops against the drifted
    estimate at their arrival and rejects true loops under large drift: ring, 0 of 26 kept). Other robust methods
    keep the iSAM2 pass's own classification (graph.incremental.classify_loops)."""

    online = True

    def __init__(self, dim: int, params: GraphParams):
        super().__init__(dim, params)
        self._inc = IncrementalPoseGraph(dim, self.online_params(params))
        self._decision: GraphResult | None = None     # the final decision, handed to iSAM2 if the graph grows

    def _resume(self) -> None:
        """The graph grows after a final decision: iSAM2 continues from it (the decided loops, at the decided
        poses), not from what its gate had admitted. Lazy, so a run that ends at `result()` pays nothing."""
        if self._decision is not None:
            self._inc.adopt(self._decision.loop_inlier, self._decision.poses)
            self._decision = None

    @staticmethod
    def online_params(params: GraphParams) -> GraphParams:
        """The iSAM2 pass classifies with its own GNC where the batch method is consensus."""
        return params.replace(robust=RobustMode.GNC) if params.robust.method == RobustMode.CONSENSUS else params

    @staticmethod
    def final_params(params: GraphParams, warm_start: bool = False) -> GraphParams:
        """The batch solve that decides the loops at the end: the batch strategy's own parameters (warm_start:
        started at the iSAM2 estimate instead of LAGO / chordal)."""
        solver = {"method": Solver.LM, **({"init": InitMethod.GIVEN} if warm_start else {})}
        return params.replace(solver=solver)

    @classmethod
    def solve(cls, data: PoseGraphData, params: GraphParams) -> GraphResult:
        """The whole graph replayed through iSAM2 in node order, as an online system would see it; then the loops
        are classified as `final` does (consensus: the batch rejector on the file's graph, loops in data order)."""
        if params.robust.method != RobustMode.CONSENSUS:
            return full_pass(data, cls.online_params(params))
        t0 = time.perf_counter()
        inc, _ = replay(data, cls.online_params(params))
        pass_seconds = time.perf_counter() - t0
        # `optimize` has anchored the components already: the batch strategy's solve, not `optimize` again
        return cls._decided(BatchStrategy.solve(data, cls.final_params(params)), inc, pass_seconds)

    @staticmethod
    def _decided(res: GraphResult, inc: IncrementalPoseGraph, pass_seconds: float) -> GraphResult:
        """The batch decision `res`, reported as the iSAM2 strategy's result (time and notes of the pass)."""
        admitted = inc.loop_inliers()
        res.seconds += pass_seconds
        res.solver = Solver.ISAM2.value            # the strategy that produced the online estimates
        res.notes.insert(0, f"iSAM2 pass {pass_seconds:.3f} s ({inc.updates} updates; the arrival gate admitted "
                            f"{int(admitted.sum())} of {len(admitted)} loops online), then the batch consensus "
                            f"solve decides every loop")
        return res

    def add_node(self, node_id: int, guess: np.ndarray | None) -> None:
        self._resume()
        self._inc.add_node(node_id, guess)

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None,
                     information: np.ndarray | None) -> None:
        self._resume()
        self._inc.add_odometry(i, j, delta, cov, information)

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None, probability: float | None,
                 information: np.ndarray | None) -> int:
        self._resume()
        return self._inc.add_loop(i, j, delta, cov, probability=probability, information=information)

    def set_guesses(self, poses: np.ndarray) -> None:
        """No-op: iSAM2 keeps its own estimate (a guess only places a node when it is added)."""

    def update(self) -> tuple[np.ndarray, np.ndarray]:
        self._inc.update()
        self._estimate = self._inc.estimate()
        return self._estimate

    def final(self, warm_start: bool) -> GraphResult:
        if self.params.robust.method != RobustMode.CONSENSUS:
            return self._inc.result(classify=True)
        # flush what is pending into the online estimate (the start of a warm-started solve), then decide every
        # loop as the batch strategy would on the same graph
        self._inc.update(final=True)
        res = optimize(self._inc.to_data(), self.final_params(self.params, warm_start))
        self._decision = res
        return self._decided(res, self._inc, self._inc.seconds)

    def to_data(self) -> PoseGraphData:
        return self._inc.to_data()

    def online_inliers(self) -> np.ndarray:
        return self._inc.loop_inliers()

    @property
    def num_nodes(self) -> int:
        return self._inc.num_nodes

    @property
    def num_loops(self) -> int:
        return self._inc.num_loops


STRATEGIES: dict[Solver, type[GraphStrategy]] = {Solver.LM: BatchStrategy, Solver.ISAM2: IncrementalStrategy}


def strategy_class(params: GraphParams) -> type[GraphStrategy]:
    """The strategy for `params.solver.method`."""
    return STRATEGIES[params.solver.method]
