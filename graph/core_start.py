"""A start for the consensus solve from the largest clusters of confident loops, grown in order of size.

Why: where the reduced graph of graph.cluster_start decides wrongly, its kept clusters hold many groups of mutually
consistent false loops between distant places, and the expansion on the full graph (GNC over the loops of its kept
clusters) factors them all: w10000 at 50 % random-grouped (seed 1): ~78000 loops, ~24000 of them false, not
finished in 10 minutes. The reduced graph keeps them because one edge per cluster is fitted by a kink of the
odometry at its ends, which the group's ten parallel loops resist on the full graph (full TLS objective 29112 at the
reduced map against 9801 at the map of every true loop).

A cluster of many loops agreeing under the calibrated noise (graph.confident) is a revisit seen over a long
stretch; a group of false loops is as large as the generator of false loops makes it (Vertigo: ten). So the core is
grown from the largest confident clusters down, one size class at a time (clusters of at least s loops, s halved
each time), each time solved on the full graph with every loop of its clusters (LAGO / chordal, warm LM, then TLS
descent within the core: a false group chained to a true revisit leaves there), and judged by the TLS objective
over every loop at its map (one residual evaluation). The growth stops before a class whose core would fill
in (its direct factorisation estimated above `core_max_cost`: the long-range edges a map of revisits does not have,
i.e. the false groups entering) or when the objective stops falling; the best map is the start. w10000 at 50 %
random-grouped (seed 1): cores of 2395 to 48945 loops (12 false), objective 23484 -> 9453, 54300 of 54312 true
loops fit at the last map and 6 of 27160 false ones; the next class (8 loops and more) would add 2163 false loops,
estimated 1.7e10 flops against 9.6e7.

The candidates outside the core that nearly fit its map join its loops when their whole confident cluster fits
once the map's own uncertainty is added (`_loose_fits`): a revisit where the core leaves the map loose.

It is one more start beside the reduced decision, made where that decision's kept clusters fill in themselves
(above `solver.direct_max_cost`: their expansion would go iterative over the false groups); the lower TLS objective
over every loop, each at its own map, wins (w10000 seed 1: 9453 at the core's map, 29112 at the reduced one's).
City10000 at 50 % random-grouped never makes it (its reduced decision's kept clusters are direct), and it would be
no start there on its own: its true clusters are small, and the core of clusters of 16 and more leaves 3946 of
10511 true loops misfitting.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.batch import initial_guess
from graph.factors import values_from_array
from graph.kernel_start import tls_descent
from graph.linear import fill_cost, narrow
from graph.trial import MapUncertainty


def core_start(cs, c2: np.ndarray) -> tuple[float, gtsam.Values, np.ndarray] | None:
    """(TLS objective over every loop at the map, the map, mask of the core's kept loops) of the best core
    (module doc), or None when no confident cluster is among the candidates or even the largest class fills in.
    `cs`: the consensus problem (graph.robust), `c2`: the thresholds of every loop."""
    return with_loose_fits(cs, c2, grow_core(cs, c2))


def with_loose_fits(cs, c2: np.ndarray, best: tuple[float, gtsam.Values, np.ndarray] | None
                    ) -> tuple[float, gtsam.Values, np.ndarray] | None:
    """The grown core (`grow_core`) with the candidates that fit its map's own uncertainty added to its loops."""
    if best is None:
        return None
    return best[:2] + (best[2] | _loose_fits(cs, c2, best[1], best[2]),)


def split_share(cs, c2: np.ndarray, core: tuple[float, gtsam.Values, np.ndarray]) -> float:
    """Share of the confident clusters with candidates outside the core that the core's map splits: some of those
    loops fit there, some do not. A map that explains the loops fits a true revisit whole and misfits a false group
    whole; a split cluster is one it strains, where it is loose or bent (the revisits it does not hold). w10000 at
    50 % random-grouped, seed 1: 1 of 5179 (a cluster of 5); city10000, seed 1: 112 of 1505 (its core of 16+
    leaves 3946 true loops misfitting)."""
    _, values, kept = core
    label = cs.confident[0]
    out = cs.cand & ~kept & (label >= 0)
    if not out.any():
        return 0.0
    fit = cs.built.subset(out).r2(values) <= c2[out]
    n = int(label.max()) + 1
    total = np.bincount(label[out], minlength=n)
    fits = np.bincount(label[out], weights=fit.astype(float), minlength=n)
    split = (fits > 0) & (fits < total)
    return float(split.sum()) / float((total > 0).sum())


def grow_core(cs, c2: np.ndarray) -> tuple[float, gtsam.Values, np.ndarray] | None:
    """The best core of the growth by size class (module doc), before the loose fits are added; None as
    `core_start`."""
    if cs.confident is None:
        return None
    params = cs.params
    label = np.where(cs.cand, cs.confident[0], -1)
    member = label >= 0
    if not member.any():
        return None
    size = np.zeros(cs.loops, np.int64)
    size[member] = np.bincount(label[member])[label[member]]
    cand = cs.built.subset(cs.cand)
    s = 1 << int(np.log2(size.max()))
    best: tuple[float, gtsam.Values, np.ndarray] | None = None
    previous = 0
    while s >= 1:
        lo, s = s, s // 2
        core = size >= lo
        n = int(core.sum())
        if n == previous:
            continue
        previous = n
        cost = fill_cost(cs.built.pairs(core), cs.data.dim)
        if cost > params.robust.core_max_cost:
            cs.notes.append(f"core start: clusters of {lo}+ loops ({n}) estimated {cost:.3g} flops, "
                            f"not solved")
            break
        with narrow(lambda: cs.built.pairs(core)):
            try:
                guess = initial_guess(cs.data, cs.stated.subset(core), cs.method)
            except RuntimeError:
                cs.notes.append("core start: LAGO / chordal on the core failed")
                break
            v, _ = cs.lm(cs.built.graph(core), values_from_array(cs.data.dim, guess),
                         params.robust.consensus_inner_iterations)
            v, kept, _ = tls_descent(cs.base, cs.built.subset(core), v, c2[core], params,
                                     params.robust.kernel_descent_rounds)
        f = cs.objective(v, c2)
        fit = int((cand.r2(v) <= c2[cs.cand]).sum())
        cs.notes.append(f"core start: clusters of {lo}+ loops, {int(kept.sum())} of {n} kept, "
                        f"{fit} of {int(cs.cand.sum())} candidates fit, TLS objective {f:.6g}")
        if best is not None and f >= best[0]:
            break
        mask = np.zeros(cs.loops, bool)
        mask[np.flatnonzero(core)[kept]] = True
        best = (f, v, mask)
    return best


def _loose_fits(cs, c2: np.ndarray, values: gtsam.Values, kept: np.ndarray) -> np.ndarray:
    """Mask of the candidates outside the core in the confident clusters (or alone, when in none) whose every loop
    outside the core misfits at its map by at most `readmit_factor` x its threshold and fits once the map's own
    uncertainty between its ends is added (graph.trial): a true revisit where the core leaves the map loose (w10000,
    seed 1: five loops closing the last 100 nodes, ATE 0.21 m without them; r^2 up to 10x their thresholds, 0.04x
    with the map's uncertainty). Whole clusters, because that loose map lets a few loops of a false group beside it
    fit too (3 of its 10 on w10000, 0.86 m once kept), and the rest of the group does not."""
    r2 = cs.built.r2(values)
    out_core = cs.cand & ~kept
    near = out_core & (r2 > c2) & (r2 <= cs.params.robust.readmit_factor * c2)
    out = np.zeros(cs.loops, bool)
    if not near.any():
        return out
    # a unit per confident cluster, a loop in none its own
    unit = np.where(cs.confident[0] >= 0, cs.confident[0], int(cs.confident[0].max()) + 1 + np.arange(cs.loops))
    _, unit = np.unique(unit, return_inverse=True)
    far = np.bincount(unit[out_core & ~near], minlength=int(unit.max()) + 1) > 0
    near &= ~far[unit]
    if not near.any():
        return out
    idx = np.flatnonzero(near)
    # a unit joins only when every near loop of it fits: its loops are asked farthest from their threshold first and
    # the unit is left at its first misfit (one joint marginal a loop, ~20 ms on 10^4 nodes)
    order = idx[np.lexsort((-(r2[idx] / c2[idx]), unit[idx]))]
    start = np.flatnonzero(np.r_[True, unit[order][1:] != unit[order][:-1]])
    m = MapUncertainty(cs.built.graph(kept), values)
    units = np.split(order, start[1:])
    # first the bound from the end poses' own marginals: a unit with a loop misfitting even that is out (w10000 at
    # 50 % random-grouped, seed 2: 302 of 312 units) without a joint marginal
    for members in units:
        loops = [(cs.built.loops[i], c2[i]) for i in members.tolist()]
        if all(m.lower(f) <= c for f, c in loops) and all(m.r2(f) <= c for f, c in loops):
            out[members] = True
    cs.notes.append(f"core start: {int(out.sum())} of {len(idx)} candidates near their thresholds fit the core "
                    f"map's own uncertainty with the rest of their cluster, added to its loops")
    return out
