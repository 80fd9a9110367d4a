"""Data snooping of the kept loops (Pope's tau test), after the decision of graph.robust, before the final polish.

The decision judges each loop at the calibrated chi-square quantile times `calibration_margin` (10): the margin
covers the heavy tail real graphs' residuals have (intel, CSAIL, garage). Where a graph's kept loops show no such
tail, the margin lets in injected loops that state the truth only roughly: w10000 at 50 % random, reporting seed 2,
keeps 14 "coincidentally true" injected loops (graph.labels) at up to 9.8x the calibrated chi-square(0.99) quantile
while its 54312 true loops reach 1.02x, and one of them (8014 -> 8035) alone moves the map 1.1 cm (1.27 cm from
the clean optimum, target 1.0 cm).

The test is the textbook one of geodesy for many observations under an estimated variance factor:

- each kept loop's studentized residual, r2_s = e^T (I - H)^-1 e / sigma0, with e its whitened error at the
  solution and H = J S J^T its leverage (J its whitened Jacobian on its two end poses, S their joint marginal
  covariance on the solved graph: odometry, anchor and the kept loops). It is the residual the loop would have at
  the map solved without it, with the map's own uncertainty between its ends added (the r2_map of graph.trial at
  that map), so a loop the map has bent towards is judged unbent, and a loose map excuses a loose loop;
- against the family-wise bound chi-square_dof^-1(1 - (1 - p) / n) for the n kept loops and the inlier probability
  p (`inlier_probability`): each of the n tests at level (1 - p) / n (Bonferroni), so a graph whose noise is
  the calibrated model loses a true loop with probability at most 1 - p;
- only where the model holds: at most a share 1 - p of the kept loops above the calibrated chi-square p quantile.
  Real graphs' heavy tails fail this (intel clean: 2.8 %), and there the margin stays the only test.

Loops above the bound leave together; the map is re-solved and tested again (at most `readmit_rounds` solves).
A dropped loop whose r2_map at the final map (graph.trial: the prediction residual with the map's uncertainty) is
within the bound comes back: an outlier beside it may have inflated its residual. Loops whose redundancy 1 - h
(h: the largest eigenvalue of H) is below `snooping_min_redundancy` are not judged: the test has no power there, and
the joint marginals of every loop cost minutes on 10^4-node graphs. A loop with r^2 / sigma0 below the bound times
that redundancy cannot exceed it, so only the loops above are judged, at most `snooping_max_loops` of them, the
largest r^2 first (w10000 clean: ~100 s against 9.5 s without a cap).
"""
from __future__ import annotations

import gtsam
import numpy as np
from scipy.stats import chi2

from graph.model import TANGENT_DIM
from graph.trial import map_mahalanobis

__all__ = ["family_bound", "heavy_tailed", "snoop", "studentized"]


def family_bound(n: int, dof: int, probability: float) -> float:
    """chi-square_dof^-1(1 - (1 - probability) / n): the Bonferroni bound of n tests at family-wise level
    1 - probability."""
    return float(chi2.ppf(1.0 - (1.0 - probability) / max(int(n), 1), dof))


def heavy_tailed(r2_units: np.ndarray, dof: int, probability: float) -> bool:
    """More than a share 1 - probability of `r2_units` (squared residuals in units of the variance factor) above the
    chi-square `probability` quantile: the residuals are heavier-tailed than the calibrated model."""
    r2 = np.asarray(r2_units, float)
    return bool(len(r2)) and float(np.mean(r2 > chi2.ppf(probability, dof))) > 1.0 - probability


def studentized(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, loops: list) -> tuple[np.ndarray, np.ndarray]:
    """(e^T (I - H)^-1 e, largest eigenvalue of H) of each factor in `loops` (between factors that are in `graph`)
    at `values`, with H = J S J^T from the marginal covariance of `graph` (module doc)."""
    out, lev = np.zeros(len(loops)), np.zeros(len(loops))
    if not loops:
        return out, lev
    marginals = gtsam.Marginals(graph, values)
    for n, f in enumerate(loops):
        lin = f.linearize(values)
        a, b = (int(k) for k in lin.keys())
        A, rhs = lin.jacobian()      # whitened; rhs = -whitened error
        d = A.shape[1] // 2
        if a == b:
            s, J = marginals.marginalCovariance(a), A[:, :d] + A[:, d:]
        else:
            jm = marginals.jointMarginalCovariance([a, b])
            s, J = np.block([[jm.at(a, a), jm.at(a, b)], [jm.at(b, a), jm.at(b, b)]]), A
        h = J @ s @ J.T
        lev[n] = float(np.linalg.eigvalsh(0.5 * (h + h.T))[-1])
        out[n] = float(rhs @ np.linalg.solve(np.eye(len(rhs)) - h, rhs))
    return out, lev


def snoop(cs, values: gtsam.Values, inlier: np.ndarray) -> tuple[gtsam.Values, np.ndarray, int]:
    """(values, inlier, LM iterations) after data snooping of the kept loops of `cs` (a graph.robust
    ConsensusProblem) at `values` (module doc)."""
    p = cs.params.robust
    prob = p.inlier_probability
    dof = TANGENT_DIM[cs.data.dim]
    built = cs.built
    # r^2 in units of the variance factor: the 2D (scalar) calibration keeps the stated information and carries
    # sigma0; the split 3D one calibrates the information itself (sigma0 = 1)
    unit = cs.sigma0
    r2 = built.r2(values) / unit
    if not inlier.any() or heavy_tailed(r2[inlier], dof, prob):
        if inlier.any():
            cs.notes.append(f"data snooping skipped: {100 * float(np.mean(r2[inlier] > chi2.ppf(prob, dof))):.2g} % of "
                            f"the kept loops above the calibrated chi-square {prob:g} quantile (heavy tail)")
        return values, inlier, 0
    start, kept = values, inlier.copy()
    iters = 0
    out = np.zeros(len(kept), bool)
    try:
        for _ in range(max(p.readmit_rounds, 1)):
            bound = family_bound(int(kept.sum()), dof, prob)
            r2 = built.r2(values) / unit
            judged = np.flatnonzero(kept & (r2 > bound * p.snooping_min_redundancy))
            if 0 < p.snooping_max_loops < len(judged):
                # the largest residuals first: a joint marginal per loop is what the test costs
                judged = judged[np.argsort(-r2[judged], kind="stable")[:p.snooping_max_loops]]
            st, lev = studentized(built.graph(kept), values, [built.loops[i] for i in judged])
            drop = judged[(st / unit > bound) & (1.0 - lev >= p.snooping_min_redundancy)]
            if not len(drop):
                break
            kept[drop] = False
            out[drop] = True
            values, it = cs.lm(built.graph(kept), values, cs.params.solver.lm_max_iterations)
            iters += it
        if out.any():
            # a loop an outlier beside it had inflated fits the unbent map within the bound: back
            idx = np.flatnonzero(out)
            back = idx[map_mahalanobis(built.graph(kept), values, [built.loops[i] for i in idx]) / unit
                       <= family_bound(int(kept.sum()) + len(idx), dof, prob)]
            if len(back):
                kept[back] = True
                out[back] = False
                values, it = cs.lm(built.graph(kept), values, cs.params.solver.lm_max_iterations)
                iters += it
    except RuntimeError as e:       # an indeterminate marginal: nothing to judge by
        cs.notes.append(f"data snooping skipped: {e}")
        return start, inlier, iters
    cs.notes.append(f"data snooping: {int(out.sum())} of {int(inlier.sum())} kept loops beyond the family-wise "
                    f"bound {family_bound(int(inlier.sum()), dof, prob) / chi2.ppf(prob, dof):.3g} x the calibrated "
                    f"chi-square {prob:g} quantile")
    return values, kept, iters
