"""The map's own uncertainty in the test of a loop against a solved map (graph.core_start: loops outside the core
that misfit its map).

A loop's residual at a map solved without it mixes two things: the loop's own error, and how far the map between
its ends may move. Under drift (a lone loop closing a long stretch of odometry) the map between its ends is loose,
and a true loop misses its threshold by a few times until the map moves to it; between two nodes of a densely looped
map it is tight, and a loop that misses there is wrong. The squared Mahalanobis distance with the marginal
covariance of the map between the two end nodes added to the loop's noise tells the two apart:

    r2_map = b^T (I + A S A^T)^-1 b

with b the loop's whitened error at the solution, A its whitened Jacobian with respect to its two end poses and S
their joint marginal covariance on the solved graph (odometry, anchor and the kept loops; gtsam.Marginals: one
factorization, then one joint marginal per loop). It never exceeds the plain r^2 = b^T b, and is compared with the
same threshold, in the units of the model the loops are judged on.
"""
from __future__ import annotations

import gtsam
import numpy as np

__all__ = ["MapUncertainty"]


class MapUncertainty:
    """r2_map (module doc) of loops against one solved map: the factorisation once, then one joint marginal per
    loop (the dear part on 10^4 nodes: ~20 ms a loop), so a caller may stop asking early."""

    def __init__(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values):
        self.values = values
        self.marginals = gtsam.Marginals(graph, values)

    def lower(self, f) -> float:
        """A lower bound of `r2` from the two end poses' own marginals (cached per clique by gtsam, far cheaper than
        their joint): Cov(Ja da + Jb db) <= 2 (Ja Saa Ja^T + Jb Sbb Jb^T), so (I + that bound)^-1 <= (I + A S A^T)^-1."""
        lin = f.linearize(self.values)
        a, b = (int(k) for k in lin.keys())
        A, rhs = lin.jacobian()
        d = A.shape[1] // 2
        if a == b:
            return self.r2(f)
        Ja, Jb = A[:, :d], A[:, d:]
        m = np.eye(len(rhs)) + 2.0 * (Ja @ self.marginals.marginalCovariance(a) @ Ja.T
                                      + Jb @ self.marginals.marginalCovariance(b) @ Jb.T)
        return float(rhs @ np.linalg.solve(m, rhs))

    def r2(self, f) -> float:
        """r2_map of the between factor `f` (not in the solved graph) at the solved values."""
        lin = f.linearize(self.values)
        a, b = (int(k) for k in lin.keys())
        A, rhs = lin.jacobian()      # whitened, columns in key order; rhs = -whitened error
        d = A.shape[1] // 2
        if a == b:
            s = self.marginals.marginalCovariance(a)
            J = A[:, :d] + A[:, d:]
        else:
            jm = self.marginals.jointMarginalCovariance([a, b])
            s = np.block([[jm.at(a, a), jm.at(a, b)], [jm.at(b, a), jm.at(b, b)]])
            J = A
        m = np.eye(len(rhs)) + J @ s @ J.T
        return float(rhs @ np.linalg.solve(m, rhs))
