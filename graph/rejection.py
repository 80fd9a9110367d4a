"""Outlier rejection for a whole graph solved in batch: one interface, one implementation per robust method.

Every robust method (`graph.robust.method`) is a `LoopRejector`: `solve(data, params)` returns a `GraphResult`
with every loop labelled. `loop_rejector(data, params)` picks the one that runs (as Kimera-RPGO puts outlier
rejection behind one interface, so the solver strategy does not know which method it holds):

- `Consensus` (`consensus`, the default): local cycle support, then GNC-TLS over the supported loops (graph.robust);
- `ArrivalGate` (`gnc`, `huber`, `cauchy` with `graph.robust.gate_loops`): the graph replayed through iSAM2 in time
  order, each loop tested against the estimate at its arrival, then the robust LM solve of the admitted loops and
  re-initialisation rounds (graph.batch.solve); it rejects true loops under large drift (docs/graph.md), so it is a
  documented choice, not the default;
- `Direct` (`none`, or a kernel / GNC without the gate): one LM solve of every loop, least squares or behind the
  method's kernel / GNC weights;
- `SplitChain`: loops are the only link between parts of the odometry chain; whatever the robust method, the ungated
  GNC solve (the gate and the consensus' odometry start both test loops against odometry, which does not reach
  across the gap: ETHCampus).
"""
from __future__ import annotations

import time
from typing import Protocol

import numpy as np

from graph.batch import solve
from graph.components import loops_join_odometry_parts
from graph.factors import anchor_nodes
from graph.incremental import gate_pass
from graph.model import TANGENT_DIM, PoseGraphData
from graph.params import GraphParams, InitMethod, RobustMode
from graph.result import GraphResult
from graph.robust import robust_solve
from graph.thresholds import loop_thresholds


class LoopRejector(Protocol):
    """A robust method: solve the whole graph and label every loop (inlier or outlier)."""

    def solve(self, data: PoseGraphData, params: GraphParams) -> GraphResult: ...


class Direct:
    """One LM solve with every loop: least squares (`none`), a Huber / Cauchy kernel, or GNC (graph.batch)."""

    def solve(self, data: PoseGraphData, params: GraphParams) -> GraphResult:
        return solve(data, params)


class Consensus:
    """Local cycle consensus, then GNC-TLS from two starts (graph.robust; the default)."""

    def solve(self, data: PoseGraphData, params: GraphParams) -> GraphResult:
        return robust_solve(data, params)


class SplitChain:
    """Loops join parts of the odometry chain: the ungated GNC solve (GNC stands in for consensus)."""

    def solve(self, data: PoseGraphData, params: GraphParams) -> GraphResult:
        gnc = params.replace(robust=RobustMode.GNC) if params.robust.method == RobustMode.CONSENSUS else params
        res = solve(data, gnc)
        res.notes.insert(0, "loops are the only link between parts of the odometry chain: solved without the gate")
        return res


class ArrivalGate:
    """The gated iSAM2 replay, then the robust solve of the admitted loops (deferred ones re-tested after)."""

    def solve(self, data: PoseGraphData, params: GraphParams) -> GraphResult:
        t0 = time.perf_counter()
        try:
            estimate, admitted = gate_pass(data, params)
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
            if tls_objective(data, alt, params) < tls_objective(data, res, params):
                alt.notes.insert(0, f"gated solve kept {int(res.loop_inlier.sum())} of {int(admitted.sum())} "
                                    "admitted loops: solved without the gate")
                return alt
        return res


def tls_objective(data: PoseGraphData, res: GraphResult, params: GraphParams) -> float:
    """cost(prior + odometry) + sum over loops of min(r^2, c^2) / 2 at the result (stated thresholds)."""
    c2 = loop_thresholds(data.probability[res.loop_edges], TANGENT_DIM[data.dim], params)
    r2 = np.asarray(res.loop_residual, float)
    base = res.final_cost - 0.5 * float(r2[res.loop_inlier].sum())     # final_cost: prior + odometry + kept loops
    return base + 0.5 * float(np.minimum(r2, c2).sum())


def loop_rejector(data: PoseGraphData, params: GraphParams) -> LoopRejector:
    """The robust method that solves this graph in batch (see the module docstring)."""
    method = params.robust.method
    if method != RobustMode.NONE and data.num_loops and loops_join_odometry_parts(data):
        return SplitChain()
    if method == RobustMode.CONSENSUS:
        return Consensus()
    if method != RobustMode.NONE and params.robust.gate_loops and data.num_loops:
        return ArrivalGate()
    return Direct()
