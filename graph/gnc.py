"""Graduated non-convexity over loop closures, with warm-started inner solves.

Yang, Antonante, Tzoumas, Carlone, "Graduated Non-Convexity for Robust Spatial Perception" (RA-L 2020), with
the trusted factors (anchor + odometry) as known inliers. The weight updates are the paper's closed forms
(the same as gtsam.GncOptimizer); the difference is in the inner solves: gtsam restarts every inner
Levenberg-Marquardt run from the initial values, while this loop continues from the previous estimate with a
few iterations, which is what makes it fast enough for 10^4-node graphs (see docs/graph.md for the
measurement). It also takes one inlier threshold per loop, which is how a loop's probability enters.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import gtsam
import numpy as np

from graph.factors import squared_residuals
from graph.linear import run_lm
from graph.params import GncLoss

_DEBUG = bool(os.environ.get("GRAPH_GNC_DEBUG"))


@dataclass
class GncOutcome:
    values: gtsam.Values
    weights: np.ndarray          # (L,) final loop weights in [0, 1]
    outer_iterations: int
    lm_iterations: int
    initial_cost: float          # least-squares cost (all loops, weight 1) at the initial values
    final_cost: float            # weighted cost at the solution


def tls_weights(r2: np.ndarray, c2: np.ndarray, mu: float) -> np.ndarray:
    """Truncated-least-squares GNC weights for squared residuals r2 and thresholds c2 (same units)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.sqrt(c2 * mu * (mu + 1.0) / r2) - mu
    w = np.where(r2 >= (mu + 1.0) / mu * c2, 0.0, w)
    w = np.where(r2 <= mu / (mu + 1.0) * c2, 1.0, w)
    return np.clip(np.nan_to_num(w, nan=1.0), 0.0, 1.0)


def gm_weights(r2: np.ndarray, c2: np.ndarray, mu: float) -> np.ndarray:
    """Geman-McClure GNC weights."""
    return (mu * c2 / (r2 + mu * c2)) ** 2


def initial_mu(loss: GncLoss, r2: np.ndarray, c2: np.ndarray) -> float:
    """The control parameter that makes the surrogate loss (nearly) convex (paper, remark 5); <= 0: nothing to do."""
    if len(r2) == 0:
        return -1.0
    if loss == GncLoss.GM:
        return float(np.max(2.0 * r2 / c2))
    excess = 2.0 * r2 - c2
    pos = excess > 0
    if not np.any(r2 > c2):
        return -1.0          # every loop already fits: plain least squares is the answer
    mu = float(np.min(c2[pos] / excess[pos]))
    return max(mu, 1e-6)


def _weighted_graph(base: gtsam.NonlinearFactorGraph, loops: list, sqrt_info: list, weights: np.ndarray,
                    cache: dict) -> gtsam.NonlinearFactorGraph:
    g = gtsam.NonlinearFactorGraph()
    g.push_back(base)
    for k, w in enumerate(weights.tolist()):
        if w >= 1.0:
            g.add(loops[k])
        elif w > 0.0:
            # quantise intermediate weights so repeated values reuse one factor
            wq = round(w, 4)
            f = cache.get((k, wq))
            if f is None:
                f = loops[k].cloneWithNewNoiseModel(gtsam.noiseModel.Gaussian.SqrtInformation(np.sqrt(wq) * sqrt_info[k]))
                cache.clear() if len(cache) > 4 * len(loops) else None
                cache[(k, wq)] = f
            g.add(f)
    return g


def gnc_optimize(base: gtsam.NonlinearFactorGraph, loops: list, init: gtsam.Values, thresholds: np.ndarray,
                 loss: GncLoss = GncLoss.TLS, mu_step: float = 1.4, max_iterations: int = 100,
                 inner_iterations: int = 10, final_iterations: int = 100, weights_tol: float = 1e-4,
                 cost_tol: float = 1e-5, rel_tol: float = 1e-5, abs_tol: float = 1e-5,
                 mu_floor: float = 0.0) -> GncOutcome:
    """Robust solve of `base` (known inliers) + `loops` (Gaussian factors to classify).

    thresholds: (L,) squared Mahalanobis residual below which a loop is an inlier (chi-square quantile).
    mu_floor: lower bound on the initial control parameter (TLS): with a warm start that already fits the inliers,
    a near-convex start (mu ~ 1e-3) only makes every loop a half-weight "maybe" for a dozen iterations.
    Returns the solution after a final solve with the converged weights.
    """
    c2 = np.asarray(thresholds, float)
    sqrt_info = [np.asarray(f.noiseModel().R(), float) for f in loops]
    cache: dict = {}
    full = gtsam.NonlinearFactorGraph()
    full.push_back(base)
    for f in loops:
        full.add(f)
    initial_cost = float(full.error(init))
    weights = np.ones(len(loops))
    # the least-squares start need not converge: with many false loops it is slow and the answer is wrong anyway
    values, lm_iters = run_lm(full, init, inner_iterations, rel_tol, abs_tol)
    r2 = squared_residuals(loops, values)
    mu = initial_mu(loss, r2, c2)
    if mu > 0 and loss == GncLoss.TLS:
        mu = max(mu, mu_floor)
    outer = 0
    if mu > 0:
        prev_cost = float(full.error(values))
        for outer in range(1, max_iterations + 1):
            new_w = tls_weights(r2, c2, mu) if loss == GncLoss.TLS else gm_weights(r2, c2, mu)
            g = _weighted_graph(base, loops, sqrt_info, new_w, cache)
            values, it = run_lm(g, values, inner_iterations, rel_tol, abs_tol)
            lm_iters += it
            r2 = squared_residuals(loops, values)
            cost = float(g.error(values))
            w_change = float(np.max(np.abs(new_w - weights))) if len(loops) else 0.0
            weights = new_w
            if _DEBUG:
                print(f"gnc {outer} mu {mu:.3g} w1 {np.sum(weights > 1 - weights_tol)} w0 {np.sum(weights < weights_tol)} "
                      f"mid {np.sum((weights >= weights_tol) & (weights <= 1 - weights_tol))} it {it} cost {cost:.4g}")
            if loss == GncLoss.TLS:
                binary = bool(np.all((weights < weights_tol) | (weights > 1.0 - weights_tol)))
                if binary and w_change < weights_tol:
                    break
                mu *= mu_step
            else:
                if mu <= 1.0 and abs(cost - prev_cost) <= cost_tol * max(prev_cost, 1e-12):
                    break
                mu = max(1.0, mu / mu_step)
            prev_cost = cost
    # final polish: for TLS the converged weights are binary; round them and solve to convergence
    final_w = (weights > 0.5).astype(float) if loss == GncLoss.TLS else weights
    g = _weighted_graph(base, loops, sqrt_info, final_w, cache)
    values, it = run_lm(g, values, final_iterations, rel_tol, abs_tol)
    lm_iters += it
    if loss == GncLoss.TLS:
        # one re-check at the polished solution: a loop the polish brought inside its threshold is re-admitted
        r2 = squared_residuals(loops, values)
        readmit = (final_w == 0) & (r2 <= c2)
        if np.any(readmit):
            final_w = np.where(readmit, 1.0, final_w)
            g = _weighted_graph(base, loops, sqrt_info, final_w, cache)
            values, it = run_lm(g, values, final_iterations, rel_tol, abs_tol)
            lm_iters += it
    return GncOutcome(values, final_w, outer, lm_iters, initial_cost, float(g.error(values)))
