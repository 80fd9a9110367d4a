"""Starts for the consensus solve decided over clusters on a reduced graph: one representative loop per cluster.

Why: on a graph with many groups of mutually consistent false loops between distant places (Vertigo's
random-grouped policy: ten loops (i+k, j+k) with one claimed pose), every group passes the local support test and
is a candidate, and any solve that holds the candidates with a non-zero weight factors thousands of long-range
edges whose fill-in is catastrophic (city10000 at 50 % random-grouped: ~1.3e11 estimated flops per factorisation
against ~1e8 clean). The confident start (graph.confident) is bent by those groups too (they agree pairwise under
the calibrated noise), rejects a confident cluster whole, and the GNC starts over every candidate then ran:
160-290 s on city10000, never finished on w10000.

The loops of one cluster of agreeing loops (graph.support: both ends within `support_window` nodes, their short
cycle closing) make one claim: they constrain the map between two stretches, and the others follow from the odometry
at either end. So the decision over clusters can be made on a reduced graph: odometry + one loop per cluster (the
middle one in time), its information multiplied by the cluster's size and its GNC threshold the sum of its loops'
thresholds (the same truncation a cluster weight of graph.tls.gnc_tls would have: the sum of n similar squared
residuals against the sum of n thresholds). Ten parallel false loops become one long-range edge, and the reduced
graph's fill-in is that of ~10^3 long-range edges (city10000 above: ~1.4e9). GNC over clusters runs there from two
starts (the odometry chain; LAGO / chordal on the representatives), and the one with the lower TLS objective on the
reduced graph is the start for the full graph (graph.robust); where the first one's decision leaves every cluster
decided at its map (kept ones fit whole, rejected ones misfit whole: `undecided_share`), the second is not made
(`cluster_decided_alone`), and a representative whose GNC weight is below the GNC's zero tolerance is out of the
step's graph (`cluster_zero_weights`). The chosen decision goes on: GNC over the loops of its kept clusters (a
false group it kept is rejected there loop by loop), then TLS descent over every candidate
(graph.kernel_start.tls_descent), which keeps the loops that fit (the false groups the reduced decision rejected do
not fit and are never factored); its TLS objective is compared with the other starts' as elsewhere. Where the loops of its kept clusters fill in
themselves (false groups the reduced graph kept: w10000), the core of the largest confident clusters
(graph.core_start) is made too, and the lower TLS objective over every loop, each at its own map, goes on.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.batch import initial_guess
from graph.core_start import core_start, grow_core, split_share, with_loose_fits
from graph.factors import values_from_array
from graph.linear import above, costly, iterative_above
from graph.support import clusters
from graph.tls import gnc_tls, tls_objective


class _Representatives:
    """The reduced loop set in the interface gnc_tls and tls_objective read (`loops`, `r2`): a few loops per cluster,
    each with its information multiplied by its share of the cluster's size."""

    def __init__(self, sub, size: np.ndarray):
        self.size = np.asarray(size, float)
        self._sub = sub
        self.loops = [f.cloneWithNewNoiseModel(gtsam.noiseModel.Gaussian.SqrtInformation(
            np.sqrt(n) * np.asarray(f.noiseModel().R(), float))) for f, n in zip(sub.loops, self.size.tolist())]

    def r2(self, values: gtsam.Values) -> np.ndarray:
        return self.size * self._sub.r2(values)


def representatives(cs, per_cluster: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(representative loops (loop indices, ascending), the cluster of each, the share of its cluster's size each
    stands for, cluster label per candidate loop) over the candidates of the consensus problem `cs` (graph.robust):
    the clusters are the connected components of the agreeing pairs among the candidates; the representatives are
    `per_cluster` loops spread evenly over the cluster in the order of their earlier end (1: the middle one; 2 or
    more: the first and the last among them), fewer where the cluster is smaller."""
    cand = np.flatnonzero(cs.cand)
    p, q = cs.pairs[0], cs.pairs[1]
    inside = cs.cand[p] & cs.cand[q]
    pos = np.full(cs.loops, -1, np.int64)
    pos[cand] = np.arange(len(cand))
    label = clusters(len(cand), pos[p[inside]], pos[q[inside]])
    a, b = cs.data.edge_index_pairs()
    idx = cs.built.loop_idx[cand]
    early = np.minimum(a[idx], b[idx])
    order = np.lexsort((early, label))              # by cluster, then in time
    sorted_label = label[order]
    first = np.flatnonzero(np.r_[True, sorted_label[1:] != sorted_label[:-1]])
    size = np.diff(np.r_[first, len(order)])
    if per_cluster <= 1:
        pick = [first + size // 2]
    else:
        pick = [first + np.rint(t * (size - 1)).astype(np.int64) for t in np.linspace(0.0, 1.0, per_cluster)]
    at = np.concatenate(pick)
    cl = np.tile(np.arange(len(first)), len(pick))
    at, u = np.unique(at, return_index=True)        # small clusters: fewer distinct picks
    cl = cl[u]
    rep = cand[order[at]]
    count = np.bincount(cl, minlength=len(first))
    share = size[cl] / count[cl]
    o = np.argsort(rep, kind="stable")
    return rep[o], cl[o], share[o], label


def cluster_starts(cs, c2: np.ndarray) -> list[tuple[str, gtsam.Values, np.ndarray]]:
    """The start from GNC over clusters on the reduced graph (module doc), from the odometry chain and from LAGO /
    chordal on odometry + the representatives, the one with the lower TLS objective on the reduced graph, or the core
    start (graph.core_start) where the loops of that one's kept clusters fill in and the core's map has the lower TLS
    objective over every loop: [(name, values, mask of the loops in its kept clusters)]. `cs`: the consensus problem (graph.robust), `c2`: the
    thresholds of every loop."""
    rep, cl, share, label = representatives(cs, cs.params.robust.cluster_representatives)
    cand = np.flatnonzero(cs.cand)
    n_cl = int(label.max()) + 1
    thresholds = np.bincount(label, weights=c2[cand], minlength=n_cl)
    count = np.bincount(cl, minlength=n_cl)
    mask = np.zeros(cs.loops, bool)
    mask[rep] = True
    # rep is ascending and the subset keeps loop order: the cluster quantities align with it
    reps = _Representatives(cs.built.subset(mask), share)
    c2_rep = thresholds[cl] / count[cl]             # a cluster's threshold split evenly over its representatives
    starts: list[tuple[float, str, gtsam.Values, np.ndarray]] = []
    cs.notes.append(f"cluster start: {n_cl} clusters of {len(cand)} candidates on the reduced graph, "
                    f"{len(rep)} representatives")
    # the reduced GNC's steps are two warm LM iterations each: where the reduced graph still fills in (its false
    # groups as long-range edges), PCG (graph.linear) instead of the direct solve. Estimated once for all its solves
    pcg = above(lambda: cs.built.pairs(mask), cs.params.robust.cluster_direct_max_cost)

    def reduced() -> object:
        return iterative_above(lambda: cs.built.pairs(mask), cs.params.robust.cluster_direct_max_cost, pcg)

    robust = cs.params.robust
    alone = robust.core_start and robust.core_alone
    guesses = [("odometry", lambda: cs.odometry_values)]
    # made only when its GNC runs (`cluster_decided_alone` may skip it)
    lago = ("representatives' LAGO / chordal",
            lambda: values_from_array(cs.data.dim, initial_guess(cs.data, cs.stated.subset(mask), cs.method)))
    # with `core_alone` the cheaper one first where the reduced graph goes PCG (w10000 at 50 % random-grouped: 5 s
    # against 63 s from the odometry chain); on a direct one the odometry chain first (`cluster_decided_alone`:
    # city10000, 2.5 s against 9.4 s CPU, and its decision the one that stands). The lower reduced objective still
    # picks between the two
    first = alone and (pcg or not robust.cluster_decided_alone)
    guesses.insert(0 if first else 1, lago)
    grown = None                                    # the core grown for `core_alone`, reused below
    for i, (name, v0) in enumerate(guesses):
        with reduced():
            try:
                start = v0()
            except RuntimeError:
                cs.notes.append("cluster start: LAGO / chordal on the representatives failed")
                continue
            v, kept, outer, _ = gnc_tls(cs.base, reps, start, c2_rep, cl, cs.params,
                                        zero_below_tol=robust.cluster_zero_weights)
            f = tls_objective(cs.base_graph, reps, v, c2_rep)
        kept_cl = np.unique(cl[kept])
        cs.notes.append(f"cluster start from {name}: GNC {outer} steps, {len(kept_cl)} of {n_cl} "
                        f"clusters kept, reduced TLS objective {f:.6g}")
        starts.append((f, f"clusters from {name}", v, _members(cs, kept_cl, label)))
        if alone and i == 0 and len(guesses) > 1 and costly(lambda: cs.built.pairs(starts[-1][3])):
            # this decision's kept clusters fill in (false groups among them): the core is made anyway; where its
            # map explains the loops and beats this decision, the other reduced GNC cannot make it lose
            grown = grow_core(cs, c2)
            if grown is not None:
                share = split_share(cs, c2, grown)
                f_reduced = cs.objective(v, c2)
                cs.notes.append(f"core alone: {share:.3g} of the confident clusters outside the core split at its "
                                f"map; TLS objective over every loop {f_reduced:.6g} at the reduced decision's map, "
                                f"{grown[0]:.6g} at the core's")
                if share <= robust.core_alone_max_split and grown[0] < f_reduced:
                    core = with_loose_fits(cs, c2, grown)
                    cs.notes.append("core alone: the other reduced GNC skipped")
                    return [("core of the largest confident clusters", core[1], core[2])]
        elif (robust.cluster_decided_alone and i == 0 and len(guesses) > 1 and kept.any()
              and not costly(lambda: cs.built.pairs(starts[-1][3]))):
            share = undecided_share(cs, c2, v, label, kept_cl)
            cs.notes.append(f"cluster start from {name}: {share:.3g} of the clusters undecided at its map")
            if share <= robust.core_alone_max_split:
                cs.notes.append("cluster start: the other reduced GNC skipped")
                break
    # only the decision with the lowest TLS objective on the reduced graph goes on to the full graph (the expansion,
    # a GNC over the loops of its clusters, is the costly part: 200 s for a losing start on city10000)
    if not starts:
        return []
    chosen = min(starts, key=lambda s: s[0])[1:]
    if robust.core_start and costly(lambda: cs.built.pairs(chosen[2])):
        # its kept clusters fill in: false groups among them, which the expansion would factor (graph.core_start)
        core = with_loose_fits(cs, c2, grown) if grown is not None else core_start(cs, c2)
        if core is not None:
            f_reduced = cs.objective(chosen[1], c2)
            cs.notes.append(f"TLS objective over every loop: {f_reduced:.6g} at the reduced decision's map, "
                            f"{core[0]:.6g} at the core's")
            if core[0] < f_reduced:
                return [("core of the largest confident clusters", core[1], core[2])]
    return [chosen]


def undecided_share(cs, c2: np.ndarray, values: gtsam.Values, label: np.ndarray, kept_clusters: np.ndarray
                    ) -> float:
    """Share of the clusters of agreeing candidates (`label`, per candidate) that a reduced decision keeping
    `kept_clusters` leaves undecided at its map `values`: a kept cluster with a loop that misfits its threshold
    `c2` there, or a rejected one with a loop that fits. One residual evaluation over the candidates.

    Why it decides: one edge per cluster lets a bent map fit a false group's representative by a kink of the
    odometry that the group's other loops do not follow, and leaves a true revisit beside such a kink with some of
    its loops out; a map that explains the loops fits every kept cluster whole and misfits every rejected one whole
    (`core_alone_max_split` asks the same of the core). City10000 at 50 % random-grouped: the decision from the
    odometry chain 0 of 2206 (seeds 1 and 2, every cluster right), the one from the representatives' LAGO 0.33 /
    0.32 (144 / 125 false clusters kept, 766 true rejected). Not a proof that the other start cannot reach a lower
    reduced objective, but the reduced objective is only the proxy: the full graph decides after it."""
    n = int(label.max()) + 1
    fit = cs.built.subset(cs.cand).r2(values) <= c2[cs.cand]
    fits = np.bincount(label, weights=fit.astype(float), minlength=n)
    total = np.bincount(label, minlength=n)
    keep = np.zeros(n, bool)
    keep[kept_clusters] = True
    undecided = np.where(keep, fits < total, fits > 0)
    return float(undecided.sum()) / float(n)


def _members(cs, kept_clusters: np.ndarray, label: np.ndarray) -> np.ndarray:
    """Mask over every loop: the candidates in the kept clusters."""
    keep = np.zeros(int(label.max()) + 1 if len(label) else 0, bool)
    keep[kept_clusters] = True
    mask = np.zeros(cs.loops, bool)
    mask[np.flatnonzero(cs.cand)[keep[label]]] = True
    return mask
