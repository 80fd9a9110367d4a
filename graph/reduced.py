"""A GNC over a few loops on the Gaussian marginal of a solved map: the cheap forecast of the joint trial.

The joint trial of the unsupported loops (graph.robust, step 4) is a GNC over the kept loops and at most
`trial_max_loops` unsupported ones, every step a warm LM solve of the whole graph (w10000 at 50 % random: ~13
solves, a quarter of the robust solve, and it keeps none of its 50 loops). What it can add is decided where those
loops end: the rest of the map only moves with them. So the same GNC is run first on a graph of just those end
poses: the known factors (anchor, odometry and the kept loops) linearised at the solution and marginalised onto the
end poses (one partial elimination, `GaussianFactorGraph.marginal`), plus the tried loops, nonlinear as they are.
Exact to first order in the map's move; the kept loops are held there, where the whole-graph trial may re-weight
them. When that GNC keeps none of the tried loops the whole-graph trial is not run (graph.robust). The re-try of
a rejected cluster (graph.groups.retry_rejected) is forecast the same way (`forced_descent`).
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.batch import lm_params
from graph.factors import graph_of, squared_residuals
from graph.kernel_start import tls_descent
from graph.linear import direct
from graph.params import GraphParams
from graph.tls import gnc_tls


class _Loops:
    """The loops of a reduced problem, as `gnc_tls` reads a `BuiltGraph` (`loops`, `r2`)."""

    def __init__(self, loops: list):
        self.loops = loops

    def r2(self, values: gtsam.Values) -> np.ndarray:
        return squared_residuals(self.loops, values)


def marginal_problem(known: list, values: gtsam.Values, loops: list, dim: int) -> tuple[list, gtsam.Values]:
    """(factors, values) of the reduced problem: the Gaussian marginal of the factors `known` at `values` on the end
    poses of `loops` (one LinearContainerFactor per factor of the marginal), and those poses."""
    keys = sorted({int(k) for f in loops for k in f.keys()})
    marginal = graph_of(known).linearize(values).marginal(keys)
    small = gtsam.Values()
    for k in keys:
        small.insert(k, values.atPose2(k) if dim == 2 else values.atPose3(k))
    return [gtsam.LinearContainerFactor(marginal.at(i), small) for i in range(marginal.size())], small


def reduced_gnc(known: list, values: gtsam.Values, loops: list, c2: np.ndarray, dim: int,
                params: GraphParams) -> np.ndarray:
    """Which of `loops` (thresholds `c2`, one GNC weight each) a GNC-TLS keeps on the marginal of the factors
    `known` at `values` (module doc)."""
    if not loops:
        return np.zeros(0, bool)
    base, small = marginal_problem(known, values, loops, dim)
    # a graph of a few hundred poses: direct, and by LM (gnc_tls's default; iSAM2 steps would only add their
    # start-up)
    with direct():
        _, kept, _, _ = gnc_tls(base, _Loops(loops), small, c2, np.arange(len(loops)), params)
    return kept


def forced_descent(known: list, values: gtsam.Values, loops: list, c2: np.ndarray, dim: int,
                   params: GraphParams) -> np.ndarray:
    """Which of `loops` (thresholds `c2`) the re-try of a rejected cluster (graph.groups.retry_rejected) keeps, on
    the marginal of the factors `known` at `values`: all of them in, LM, then TLS descent over them (module doc;
    the known factors are held at their linearisation, where the whole-graph re-try may drop kept loops)."""
    if not loops:
        return np.zeros(0, bool)
    base, small = marginal_problem(known, values, loops, dim)
    with direct():
        g = graph_of(base + loops)
        v = gtsam.LevenbergMarquardtOptimizer(g, small, lm_params(params, graph=g)).optimize()
        _, kept, _ = tls_descent(base, _Loops(loops), v, c2, params, params.robust.kernel_descent_rounds)
    return kept
