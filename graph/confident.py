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

It runs first when some candidate misfits at that map (else the supported start and its GNC follow as before,
as on clean graphs). When every confident cluster keeps at least one of its loops after the descent, it is the only start
(and the supported start, whose LAGO and LM factor every chance-supported long-range false loop, is not made): the
GNC starts exist for groups of mutually consistent false loops that bend the consensus, and a confident cluster
rejected whole is such a hypothesis the confident map disagrees with. Otherwise it is one more start beside them
and the lowest TLS objective wins. The group test, re-admission and the trial of the unsupported loops follow
either way.
"""
from __future__ import annotations

import gtsam
import numpy as np
from scipy.stats import chi2

from graph.batch import initial_guess
from graph.factors import values_from_array
from graph.linear import narrow
from graph.model import TANGENT_DIM
from graph.params import GraphParams, InitMethod
from graph.support import CycleSupport, clusters


def confident_loops(cycles: CycleSupport, num_loops: int, dof: int, scale: float, params: GraphParams) -> np.ndarray:
    """Cluster label per loop, -1 for a loop that is not confident: the clusters of at least
    `confident_min_cluster` loops whose agreeing pairs pass the cycle test at chi-square(`support_probability`,
    dof) x `scale` (the variance factor of the agreeing cycles) on the stated covariances."""
    p, q, r2 = cycles.pairs
    ok = r2 <= float(chi2.ppf(params.robust.support_probability, dof)) * scale
    if not ok.any():
        return np.full(num_loops, -1, np.int64)
    label = clusters(num_loops, p[ok], q[ok])
    size = np.bincount(label)
    return np.where(size[label] >= max(params.robust.confident_min_cluster, 2), label, -1)


def confident_start(cs, supported: np.ndarray):
    """(cluster label per loop, -1 for a loop that is not confident; thunk giving the start from the confident
    loops: LAGO / chordal on them, then warm LM, computed on first use), or None when off or when no loop is
    confident. `cs`: the consensus problem (graph.robust), whose agreeing cycles are tested on the stated covariances
    at their variance factor (with the split 3D calibration, its single factor)."""
    params = cs.params
    if not params.robust.confident_start:
        return None
    scale = cs.sigma0 if cs.factors is None else cs.factors.scalar
    label = confident_loops(cs.cycles, cs.loops, TANGENT_DIM[cs.data.dim], scale, params)
    label[~supported] = -1
    mask = label >= 0
    if not mask.any():
        return None
    cache: list = []

    def start() -> gtsam.Values:
        if not cache:
            cs.notes.append(f"confident loops: {int(mask.sum())} of {int(supported.sum())} supported")
            try:
                guess = initial_guess(cs.data, cs.stated.subset(mask), cs.method)
            except RuntimeError:
                guess = initial_guess(cs.data, cs.stated, InitMethod.ODOMETRY)
            with narrow(lambda: cs.built.pairs(mask)):
                cache.append(cs.lm(cs.built.graph(mask), values_from_array(cs.data.dim, guess),
                                   params.robust.consensus_inner_iterations)[0])
        return cache[0]
    return label, start


def confident_first(cs, c2: np.ndarray) -> bool:
    """Whether the confident start is to be tried before the GNC starts: some candidate misfits at it (else the
    supported start fits too, as on clean graphs, and its GNC takes no step)."""
    if cs.confident is None:
        return False
    return bool(np.any(cs.built.subset(cs.cand).r2(cs.confident[1]()) > c2[cs.cand]))


def confident_holds(cs, inlier: np.ndarray) -> bool:
    """Whether the decision from the confident start stands alone: every confident cluster keeps at least one of its
    loops. A cluster rejected whole is a consensus hypothesis the map solved from the confident loops disagrees with:
    a group of mutually consistent false loops among them (bending that map, or rejected by it) or true loops it
    strains; then the GNC starts run as well and the lowest TLS objective wins. A few false loops that agree with
    the true loops of a revisit sit in its cluster and leave alone (w10000 at 50 % random: 2 of 54319)."""
    conf = cs.confident[0] >= 0
    return _every_cluster_has(cs.confident[0], inlier[conf])


def confident_whole(cs, c2: np.ndarray) -> bool:
    """Whether every confident cluster has at least one loop that fits at the map of the confident loops (before
    any descent): a cluster that misfits whole there is one the descent from it would reject whole, so the
    confident start would not stand alone (`confident_holds`)."""
    return whole_misfit_share(cs, c2) == 0.0


def whole_misfit_share(cs, c2: np.ndarray) -> float:
    """Share of the confident clusters none of whose loops fits its threshold at the map of the confident loops."""
    conf = cs.confident[0] >= 0
    missing, present = _clusters_without(cs.confident[0], cs.built.subset(conf).r2(cs.confident[1]()) <= c2[conf])
    return missing / max(present, 1)


def _every_cluster_has(label: np.ndarray, hit: np.ndarray) -> bool:
    """Whether every confident cluster (`label` per loop, -1: in none) has a loop with `hit` (one flag per loop of
    a cluster, in loop order)."""
    return _clusters_without(label, hit)[0] == 0


def _clusters_without(label: np.ndarray, hit: np.ndarray) -> tuple[int, int]:
    """(confident clusters without a loop with `hit`, confident clusters) for `label` / `hit` as in
    `_every_cluster_has`."""
    conf = label >= 0
    n = int(label.max()) + 1
    count = np.bincount(label[conf], weights=np.asarray(hit, float), minlength=n)
    present = np.bincount(label[conf], minlength=n) > 0
    return int(np.sum(present & (count <= 0))), int(present.sum())
