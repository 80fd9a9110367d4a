"""Which accepted loops to doubt: isolated loops whose standardized residual says the map bent to fit them.

A false loop can fit its own threshold because the solution bent around it; its residual then looks normal. The
standardized residual (Baarda's w-test) divides by the residual's own variance, I - A S A^T in whitened units, with
S the joint marginal covariance of the two poses and A the loop's whitened Jacobian: a loop that alone holds the map
in its shape has leverage close to 1 and a large statistic. Joint marginals cost about a millisecond each, so only
isolated loops are tested: true loops come in runs (a revisit closes several consecutive pairs), random false loops
do not.
"""
from __future__ import annotations

import gtsam
import numpy as np
from scipy.spatial import cKDTree


def isolated(pos_a: np.ndarray, pos_b: np.ndarray, kept: np.ndarray, window: int) -> np.ndarray:
    """Kept loops with no other kept loop within `window` nodes at both ends (node positions, either orientation)."""
    lo = np.minimum(pos_a, pos_b).astype(float)
    hi = np.maximum(pos_a, pos_b).astype(float)
    out = np.zeros(len(lo), bool)
    idx = np.flatnonzero(kept)
    if len(idx) < 2:
        out[idx] = True
        return out
    pts = np.column_stack([lo[idx], hi[idx]])
    counts = np.asarray([len(n) for n in cKDTree(pts).query_ball_point(pts, r=window, p=np.inf)])
    out[idx] = counts <= 1
    return out


def standardized_residuals(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, factors: list,
                           which: np.ndarray) -> np.ndarray:
    """w_k = b^T (I - A S A^T)^-1 b for the loop factors selected by `which` (inf where the residual variance
    vanishes: the loop is the only thing holding the map); NaN for the others."""
    out = np.full(len(factors), np.nan)
    sel = np.flatnonzero(which)
    if len(sel) == 0:
        return out
    try:
        marginals = gtsam.Marginals(graph, values)
    except RuntimeError:
        # indeterminate: the kept loops leave part of the map tied to nothing (ETHCampus once its bridging loops
        # are rejected). No variance, no test: the loops stay as the other proposals label them
        return out
    for k in sel.tolist():
        f = factors[k]
        ki, kj = list(f.keys())
        A, b = f.linearize(values).jacobian()
        jm = marginals.jointMarginalCovariance(gtsam.KeyVector([ki, kj]))
        S = np.block([[jm.at(ki, ki), jm.at(ki, kj)], [jm.at(kj, ki), jm.at(kj, kj)]])
        var = np.eye(len(b)) - A @ S @ A.T
        try:
            ev = np.linalg.eigvalsh(0.5 * (var + var.T))
            out[k] = float(b @ np.linalg.solve(var, b)) if ev[0] > 1e-9 else np.inf
        except np.linalg.LinAlgError:
            out[k] = np.inf
    return out
