"""The batch front door: `optimize(data, params)` picks the solver (batch LM, or a full iSAM2 pass) and, for robust
modes, runs the gated incremental pass before the batch robust solve (see `graph.batch` and `graph.incremental`).
"""
from __future__ import annotations

import time

import numpy as np

from graph import incremental
from graph.batch import solve
from graph.components import anchor_components, loops_join_odometry_parts
from graph.errors import GraphError
from graph.factors import anchor_nodes
from graph.model import TANGENT_DIM, PoseGraphData
from graph.params import GraphParams, InitMethod, RobustMode, Solver
from graph.result import GraphResult
from graph.robust import robust_solve
from graph.thresholds import loop_thresholds


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
        res = _optimize(data, params)
    except GraphError:
        raise
    except (RuntimeError, IndexError, ValueError) as exc:
        plain = params.replace(solver={"method": Solver.LM, "init": InitMethod.ODOMETRY},
                               robust={"gate_loops": False})
        try:
            res = _optimize(data, plain)
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


def _optimize(data: PoseGraphData, params: GraphParams) -> GraphResult:
    if params.solver.method == Solver.ISAM2:
        # the incremental pass gates loops on arrival and classifies them with its own GNC
        inc = params.replace(robust=RobustMode.GNC) if params.robust.method == RobustMode.CONSENSUS else params
        return incremental.full_pass(data, inc)
    if params.robust.method != RobustMode.NONE and data.num_loops and loops_join_odometry_parts(data):
        # the gate and the consensus' odometry-chain start both test loops against odometry, which does not reach
        # across the gap (ETHCampus: the far part ends metres off); the ungated GNC solve keeps those loops
        gnc = params.replace(robust=RobustMode.GNC) if params.robust.method == RobustMode.CONSENSUS else params
        res = solve(data, gnc)
        res.notes.insert(0, "loops are the only link between parts of the odometry chain: solved without the gate")
        return res
    if params.robust.method == RobustMode.CONSENSUS:
        return robust_solve(data, params)
    if params.robust.method != RobustMode.NONE and params.robust.gate_loops and data.num_loops:
        t0 = time.perf_counter()
        try:
            estimate, admitted = incremental.gate_pass(data, params)
        except (ValueError, RuntimeError) as exc:
            # a node order the replay cannot follow (a node linked only to later nodes): solve ungated
            res = solve(data, params)
            res.notes.insert(0, f"gate pass impossible, solved without it: {exc}".splitlines()[0])
            return res
        gate_seconds = time.perf_counter() - t0
        seeded = data.copy()
        seeded.poses = estimate
        # the gate pass anchors node 0 only: other anchors (FIX, one per component) keep their given poses
        anc = anchor_nodes(data)
        given = anc[data.has_pose[anc]]
        seeded.poses[given] = data.poses[given]
        res = solve(seeded, params.replace(solver={"init": InitMethod.GIVEN}), candidates=admitted)
        res.seconds += gate_seconds
        res.init_seconds += gate_seconds
        res.init = f"gated iSAM2 pass ({int(admitted.sum())} of {len(admitted)} loops admitted)"
        res.notes.insert(0, f"gate pass {gate_seconds:.3f} s: {int((~admitted).sum())} loops deferred")
        if res.loop_inlier.sum() < params.robust.gate_fallback_share * admitted.sum():
            # the robust solve threw out most of what the gate admitted: the gate's estimate was a bad start
            # (sphere2500 at 10 %: every loop rejected). Solve without the gate; keep the lower TLS objective.
            alt = solve(data, params)
            alt.seconds += res.seconds
            if _tls_objective(data, alt, params) < _tls_objective(data, res, params):
                alt.notes.insert(0, f"gated solve kept {int(res.loop_inlier.sum())} of {int(admitted.sum())} "
                                    "admitted loops: solved without the gate")
                return alt
        return res
    return solve(data, params)


def _tls_objective(data: PoseGraphData, res: GraphResult, params: GraphParams) -> float:
    """cost(prior + odometry) + sum over loops of min(r^2, c^2) / 2 at the result (stated thresholds)."""
    c2 = loop_thresholds(data.probability[res.loop_edges], TANGENT_DIM[data.dim], params)
    r2 = np.asarray(res.loop_residual, float)
    base = res.final_cost - 0.5 * float(r2[res.loop_inlier].sum())     # final_cost: prior + odometry + kept loops
    return base + 0.5 * float(np.minimum(r2, c2).sum())


