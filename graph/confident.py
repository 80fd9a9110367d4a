"""A start for the consensus solve from the confidently supported loops only (in the spirit of PCM, Kimera-RPGO).

Why: the support test (graph.support) runs on the stated noise, which public graphs state 10-1000x too loose
(w10000: variance factor 0.0024), so on a densely looped graph many random false loops find an agreeing
neighbour by chance, mostly a true loop of a revisit next to them (w10000 at 50 % random false loops: 6222 of
27156). GNC over all supported loops starts from its convex surrogate, where those thousands of long-range false
loops pull with nearly full weight, and settles in a bent minimum (w10000, seed 1: 38.9 m from the clean optimum,
TLS objective 2118 against 1992 at the clean optimum); both GNC starts and the DCS-kernel start end there.

The confident loops are those in a cluster of at least `confident_min_cluster` loops agreeing pairwise under the
calibrated noise (the chi-square quantile of the cycle test times the variance factor of the agreeing cycles,
without the heavy-tail margin of the loop thresholds: a loop left out of the confident set is still a candidate,
one let in bends the start) instead of the stated one. A random false loop rarely agrees that closely with a
neighbour, and almost never with two (w10000 as above: 8 false loops against 54311 of 54312 true ones, all 8 beside
true loops they agree with; with the margin, 62, twelve of them in clusters of false loops alone that a grid's
repeated turns make agree, which bent the start by 14 m). The map solved on odometry + those loops (LAGO /
chordal, then a few LM iterations) never holds the chance-supported false loops (w10000: 0.57 m from the clean
optimum); TLS descent over every candidate from it (graph.kernel_start.tls_descent: keep the loops that fit,
re-solve) then decides (one re-solve, TLS objective 1992.03, every label right).

When every confident loop fits its threshold at that map, it is the only start: the GNC starts exist for groups of
mutually consistent false loops that bend the consensus, and a group bending the confident map leaves confident
loops that do not fit there (the supported start's rule, graph.robust, applied to the confident loops). Otherwise
it is one more start beside them and the lowest TLS objective wins. The group test, re-admission and the trial
of the unsupported loops follow either way.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from graph.params import GraphParams
from graph.support import CycleSupport, clusters


def confident_loops(cycles: CycleSupport, num_loops: int, dof: int, scale: float, params: GraphParams) -> np.ndarray:
    """Mask over the loops: in a cluster of at least `confident_min_cluster` loops whose agreeing pairs pass the
    cycle test at chi-square(`support_probability`, dof) x `scale` (the variance factor of the agreeing cycles)
    on the stated covariances."""
    p, q, r2 = cycles.pairs
    ok = r2 <= float(chi2.ppf(params.robust.support_probability, dof)) * scale
    if not ok.any():
        return np.zeros(num_loops, bool)
    label = clusters(num_loops, p[ok], q[ok])
    size = np.bincount(label)
    return size[label] >= max(params.robust.confident_min_cluster, 2)
