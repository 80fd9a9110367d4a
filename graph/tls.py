"""Truncated least squares over loop closures: the objective, its GNC (one weight per cluster of loops) and the
admission of loops that fit at a solution. The pieces every step of the consensus solve (graph.robust) shares.

TLS charges a loop min(r^2, c^2) / 2: a loop beyond its threshold c^2 costs a constant and pulls nothing, so the
objective compares loop sets directly. GNC (Yang et al. 2020) reaches it from a convex surrogate by a rising mu.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.batch import BuiltGraph, solve_lm
from graph.factors import graph_of
from graph.gnc import tls_weights
from graph.params import GraphParams


def weighted_graph(base_factors: list, loops: list, weights: np.ndarray) -> gtsam.NonlinearFactorGraph:
    g = graph_of(base_factors)
    for f, w in zip(loops, weights.tolist()):
        if w >= 1.0 - 1e-9:
            g.add(f)
        elif w > 1e-9:
            r = np.asarray(f.noiseModel().R(), float)
            g.add(f.cloneWithNewNoiseModel(gtsam.noiseModel.Gaussian.SqrtInformation(np.sqrt(w) * r)))
    return g


def gnc_tls(base: list, sub: BuiltGraph, values: gtsam.Values, c2: np.ndarray, label: np.ndarray,
            params: GraphParams) -> tuple[gtsam.Values, np.ndarray, int, int]:
    """GNC-TLS over the loops of `sub` from `values` with one weight per label (cluster); returns (values,
    inlier per loop, outer steps, LM iterations). Odometry + anchor (`base`) are known inliers."""
    loops = sub.loops
    L = len(loops)
    n_cl = int(label.max()) + 1 if L else 0
    c2_cl = np.bincount(label, weights=c2, minlength=n_cl) if L else np.zeros(0)
    weights = np.ones(n_cl)
    outer = iters = 0
    if not L:
        return values, np.zeros(0, bool), 0, 0
    r2_cl = np.bincount(label, weights=sub.r2(values), minlength=n_cl)
    excess = 2.0 * r2_cl - c2_cl
    if np.any(r2_cl > c2_cl):
        pos = excess > 0
        mu = max(float(np.min(c2_cl[pos] / excess[pos])), 1e-6)
        tol = params.robust.gnc_weights_tol
        for outer in range(1, params.robust.gnc_max_iterations + 1):
            new_w = tls_weights(r2_cl, c2_cl, mu)
            inner = params.robust.consensus_inner_iterations
            if (params.robust.consensus_binary_converge and outer > 1
                    and bool(np.all((new_w < tol) | (new_w > 1 - tol)))
                    and float(np.max(np.abs(new_w - weights))) >= tol):
                # binary weights that still change: the surrogate is TLS itself from here on, and a few warm
                # iterations per step only creep towards the next labels (a label-flip tail of 40+ steps)
                inner = params.solver.lm_max_iterations
            values, it = solve_lm(weighted_graph(base, loops, new_w[label]), values, params, inner)
            iters += it
            r2_cl = np.bincount(label, weights=sub.r2(values), minlength=n_cl)
            change = float(np.max(np.abs(new_w - weights)))
            weights = new_w
            if bool(np.all((weights < tol) | (weights > 1 - tol))) and change < tol:
                break
            mu *= params.robust.consensus_mu_step
    return values, (weights > 0.5)[label], outer, iters


def tls_objective(base_graph: gtsam.NonlinearFactorGraph, loops: BuiltGraph, values: gtsam.Values,
                  c2: np.ndarray) -> float:
    """The truncated-least-squares objective: cost(anchor + odometry) + sum over the loops of `loops` of
    min(r^2, c^2) / 2."""
    return float(base_graph.error(values)) + 0.5 * float(np.minimum(loops.r2(values), c2).sum())


def admit_fitting(built, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray, params: GraphParams,
             notes: list[str]) -> tuple[gtsam.Values, np.ndarray, int]:
    """Admit every loop that fits its threshold at the solution and re-solve, until none is added (at most
    `readmit_rounds` solves)."""
    iters = 0
    for _ in range(params.robust.readmit_rounds):
        readmit = ~inlier & (built.r2(values) <= c2)
        if not readmit.any():
            break
        inlier = inlier | readmit
        values, it = solve_lm(built.graph(inlier), values, params, params.solver.lm_max_iterations)
        iters += it
        notes.append(f"admitted {int(readmit.sum())} loops that fit at the solution")
    return values, inlier, iters
