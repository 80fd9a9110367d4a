"""The group-level test of the consensus solve (step 4 of graph.robust): a kept cluster of loops from one revisit is
one hypothesis, dropped when the TLS objective is lower without it.
"""
from __future__ import annotations

import gtsam
import numpy as np
from scipy.stats import chi2

from graph.batch import BuiltGraph, initial_guess, solve_lm
from graph.factors import graph_of, values_from_array
from graph.kernel_start import tls_descent
from graph.model import TANGENT_DIM, PoseGraphData
from graph.params import GraphParams, InitMethod, LoopWeighting
from graph.reduced import forced_descent
from graph.support import revisits
from graph.tls import tls_objective


def group_threshold(probability: np.ndarray, dof: int, scale: float, params: GraphParams,
                    odometry_factor: float = 0.0) -> float:
    """Truncation level of a cluster of n loops judged as one hypothesis: the chi-square quantile of its summed
    squared residuals (n x dof degrees of freedom), shifted by the log-odds of its mean loop probability (as a
    single loop's, graph.thresholds), times the calibration scale of the loop thresholds. With
    `group_margin_once` (calibrated models only), the scale's heavy-tail margin (`calibration_margin`) is granted
    once, on one loop's chi-square quantile, and the sum is held to the variance factor alone: the margin covers
    one loop far in its tail (intel's true lone loops reach 12x chi-square), while n loops of one revisit are one
    claim whose n x dof sum has no such tail of its own. The sum is held to the larger of the variance factor and
    `odometry_factor` (`odometry_variance` at the solution), and never above the threshold with the margin on the
    whole sum: where the odometry itself disagrees with the map (a heading bias the short agreeing cycles do not
    see: 34x against 1.02 in the drift test of tests/graph/test_consensus.py), a true revisit strains it by more
    than one loop's margin, and the group test must not read that strain as a false group's bend (ringCity
    random-grouped: 0.027 against 0.128)."""
    n = len(probability)
    c2 = float(chi2.ppf(params.robust.inlier_probability, n * dof))
    p = probability[np.isfinite(probability)]
    if len(p) and params.robust.loop_weighting == LoopWeighting.THRESHOLD:
        pc = float(np.clip(p.mean(), params.robust.probability_clip, 1.0 - params.robust.probability_clip))
        c2 = max(c2 + 2.0 * np.log(pc / (1.0 - pc)), 0.05 * c2)
    if params.robust.group_margin_once and scale != 1.0:
        # the heavy-tail margin once, for the worst loop of the claim; the rest at the chi-square of n x dof
        unit = scale / params.robust.calibration_margin
        once = c2 * max(unit, odometry_factor) + (scale - unit) * float(chi2.ppf(params.robust.inlier_probability, dof))
        return min(once, c2 * scale)
    return c2 * scale


def odometry_variance(built: BuiltGraph, values: gtsam.Values, dof: int) -> float:
    """A-posteriori variance factor of the odometry at `values`: its summed squared residuals over its degrees of
    freedom, in the units of `built`'s information."""
    if not built.odometry:
        return 0.0
    return 2.0 * graph_of(built.odometry).error(values) / (len(built.odometry) * dof)


def _joint_screen(built: BuiltGraph, values: gtsam.Values, inlier: np.ndarray, component: np.ndarray,
                  order: np.ndarray, c2: np.ndarray, params: GraphParams, notes: list[str]) -> tuple[np.ndarray, int]:
    """The clusters of `order` still worth a test of their own: one warm solve with every one of them left out at
    once, and those whose loops all fit their thresholds there are passed (cost: one screen instead of one per
    cluster; clean city10000 and w10000 spent 2.8 s and 7.6 s in ten screens that dropped nothing).

    Leaving more out only loosens the map around each cluster (its loops are predicted from less), so a cluster
    that still fits with all of them out would, in all but contrived layouts, also fit with only itself out; a
    cluster that bent the map does not fit once the map unbends, whatever else is out. The others go through
    the test of their own, in the same order as before."""
    if not params.robust.group_joint_screen or len(order) < 2:
        return order, 0
    tested = np.isin(component, order)
    v, it = solve_lm(built.graph(inlier & ~tested), values, params, params.robust.consensus_inner_iterations)
    misfit = tested & (built.r2(v) > c2)
    left = order[np.isin(order, component[misfit])]
    notes.append(f"group test: {len(order) - len(left)} of {len(order)} clusters passed by the joint screen")
    return left, it


def drop_false_groups(data: PoseGraphData, built, base_graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                       inlier: np.ndarray, c2: np.ndarray, scale: float, init: InitMethod, params: GraphParams,
                       notes: list[str], start_built: BuiltGraph | None = None) -> tuple[gtsam.Values, np.ndarray, int]:
    """The group-level test: each kept revisit cluster (graph.support.revisits) is one hypothesis in the TLS
    objective, truncated at its group threshold (`group_threshold`); a cluster is dropped when the map solved
    without it has the lower objective.

    A group of mutually consistent false loops supports itself in the cycle test, and once the map has bent to it
    every one of its loops fits its own threshold: per-loop GNC weights cannot see it, the strain sits in the
    odometry (a known inlier, never truncated). Per loop, rejecting the group would cost n loop thresholds, each
    with the heavy-tail margin and the probability shift (ring random-grouped: 10 x 44 against ~140 of bending);
    but n loops of one event are one claim, and the sum of n squared residuals has a far lighter tail than one, so
    the group is truncated at the chi-square quantile of n x dof. A true cluster stays: removing it leaves its
    loops either still fitting (the rest of the map agrees: no re-solve is needed) or the map drifting by the
    amount the cluster corrected, which costs it its group threshold and more. Cost: one warm LM solve per
    tested cluster (the `group_tests` whose loops sit nearest their thresholds) screens with a few warm LM
    iterations; full warm and LAGO / chordal re-solves only for a cluster whose loops no longer fit without it.
    `start_built`: the graph whose LAGO / chordal guess starts those re-solves (default `built`).
    """
    iters = 0
    budget = params.robust.group_tests
    if budget <= 0 or not inlier.any():
        return values, inlier, 0
    dof = TANGENT_DIM[data.dim]
    component, groups = kept_clusters(data, inlier, params.robust.support_window)
    if not len(groups):
        return values, inlier, 0
    ratio = _cluster_ratio(built.r2(values), c2, component, groups)
    order = groups[np.argsort(-ratio, kind="stable")][:budget]
    prob = data.probability[built.loop_idx]
    odometry_factor = odometry_variance(built, values, dof) if params.robust.group_margin_once else 0.0
    dropped = 0
    order, it = _joint_screen(built, values, inlier, component, order, c2, params, notes)
    iters += it

    def objective(v: gtsam.Values, member: np.ndarray, c2g: float) -> float:
        return group_objective(base_graph, built, v, c2, [(member, c2g)])

    for g in order.tolist():
        member = component == g
        trial = inlier & ~member
        # screen with a few warm iterations (one full solve per cluster tripled city10000 clean): the map moves
        # most of the way at once, so a cluster whose loops still fit then is not what bends the map
        v, it = solve_lm(built.graph(trial), values, params, params.robust.consensus_inner_iterations)
        iters += it
        if np.all(built.r2(v)[member] <= c2[member]):
            continue
        v, it = solve_lm(built.graph(trial), v, params, params.solver.lm_max_iterations)
        iters += it
        c2g = group_threshold(prob[member], dof, scale, params, odometry_factor)
        f0 = objective(values, member, c2g)
        v, f, it = lower_of_fresh_start(data, built, trial, v, lambda x: objective(x, member, c2g), init, params,
                                        start_built)
        iters += it
        if f < f0:
            values, inlier = v, trial
            dropped += int(member.sum())
    if dropped:
        notes.append(f"group test: dropped {dropped} loops in clusters that lowered the TLS objective by leaving")
    return values, inlier, iters


def kept_clusters(data: PoseGraphData, inlier: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """(revisit-cluster label per loop over the kept loops (graph.support.revisits), the labels of the clusters of
    2+ kept loops): a lone loop is GNC's to judge, one weight each."""
    component = revisits(data, window, inlier)
    labels, counts = np.unique(component[inlier], return_counts=True)
    return component, labels[counts >= 2]


def lower_of_fresh_start(data: PoseGraphData, built: BuiltGraph, trial: np.ndarray, warm: gtsam.Values,
                         objective, init: InitMethod, params: GraphParams, start_built: BuiltGraph | None = None
                         ) -> tuple[gtsam.Values, float, int]:
    """(values, objective, LM iterations): the map solved with the loops of `trial` from a fresh LAGO / chordal
    start (on `start_built`'s information, default `built`) where its `objective` is lower than at `warm` (already
    solved with them), else `warm`. A map bent by tens of metres does not unbend by local steps (ring
    random-grouped: a local minimum above the objective with the group kept)."""
    f = objective(warm)
    try:
        start = built if start_built is None else start_built
        guess = values_from_array(data.dim, initial_guess(data, start.subset(trial), init))
        v2, it = solve_lm(built.graph(trial), guess, params, params.solver.lm_max_iterations)
    except RuntimeError:
        return warm, f, 0
    f2 = objective(v2)
    return (v2, f2, it) if f2 < f else (warm, f, it)


def _cluster_ratio(r2: np.ndarray, c2: np.ndarray, component: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Per cluster label in `groups`: its loops' summed r^2 over their summed thresholds (the order in which the
    group test and the re-try take clusters)."""
    return np.array([r2[component == g].sum() / c2[component == g].sum() for g in groups.tolist()])


def group_objective(base_graph: gtsam.NonlinearFactorGraph, built: BuiltGraph, values: gtsam.Values,
                    c2: np.ndarray, groups: list[tuple[np.ndarray, float]]) -> float:
    """The TLS objective (graph.tls.tls_objective) with each of `groups` (loop mask, group threshold) charged as one
    hypothesis, min(sum r^2, c2g) / 2, instead of loop by loop: the model the group test decides by."""
    r = built.r2(values)
    f = tls_objective(base_graph, built, values, c2)
    for member, c2g in groups:
        f += 0.5 * (min(float(r[member].sum()), c2g) - float(np.minimum(r[member], c2[member]).sum()))
    return f


def retry_rejected(data: PoseGraphData, built: BuiltGraph, base_graph: gtsam.NonlinearFactorGraph,
                   values: gtsam.Values, inlier: np.ndarray, cand: np.ndarray, c2: np.ndarray, scale: float,
                   params: GraphParams, notes: list[str], budget: int | None = None
                   ) -> tuple[gtsam.Values, np.ndarray, int]:
    """Re-try the supported revisit clusters (graph.support.revisits over `cand`) rejected whole: each of the
    `retry_clusters` nearest their thresholds (summed r^2 over summed c2) goes back with every kept loop, LM from
    the solution, then TLS descent over the kept loops and it (the misfits leave, re-solve); the new set stands
    when the group-level objective (`group_objective`, the cluster and every kept cluster the descent dropped
    charged as one hypothesis each) is lower than before.

    The GNC starts decide every cluster at once from one map; when a bend elsewhere holds a true revisit off, GNC
    truncates it and no later step offers it back whole (per-loop readmission sees each of its loops misfit at the
    bent map). Charging the clusters at their group thresholds keeps the move consistent with the group test: a
    false group it dropped does not come back because sixteen per-loop thresholds outweigh one bend. Cost: one LM
    solve and a TLS descent per tried cluster; the order puts the thousands of false groups of a 10^4-node graph,
    off by 10^3-10^4 times their thresholds, last. `budget`: clusters tried (default `retry_clusters`)."""
    budget = params.robust.retry_clusters if budget is None else budget
    out = cand & ~inlier
    if budget <= 0 or not out.any():
        return values, inlier, 0
    window = params.robust.support_window
    component = revisits(data, window, cand)
    labels, counts = np.unique(component[cand], return_counts=True)
    kept_labels = np.unique(component[cand & inlier])
    whole = labels[(counts >= 2) & ~np.isin(labels, kept_labels)]
    if not len(whole):
        return values, inlier, 0
    ratio = _cluster_ratio(built.r2(values), c2, component, whole)
    order = whole[np.argsort(ratio, kind="stable")][:budget]
    dof = TANGENT_DIM[data.dim]
    prob = data.probability[built.loop_idx]
    base = built.priors + built.odometry
    iters = 0
    added = 0
    def kept_factors(mask: np.ndarray) -> list | None:
        # the forecast's known factors: the kept loops of the solution it is made on
        return base + [f for f, k in zip(built.loops, mask.tolist()) if k] if params.robust.retry_forecast else None

    known = kept_factors(inlier)
    skipped = 0
    for g in order.tolist():
        member = component == g
        if params.robust.retry_forecast:
            # the re-try first on the marginal of the solved map on the cluster's ends (graph.reduced): when none of
            # its loops survives there, the whole-graph solve with it forced in is not made (city10000 at 50 %
            # random: 3 chance-agreeing false pairs, ~13 s of LM each, all dropped again)
            idx = np.flatnonzero(member)
            try:
                survives = forced_descent(known, values, [built.loops[i] for i in idx], c2[idx], data.dim,
                                          params).any()
            except RuntimeError:            # an indeterminate marginal: no forecast, the re-try runs
                survives = True
            if not survives:
                skipped += 1
                continue
        trial = inlier | member
        v, it = solve_lm(built.graph(trial), values, params, params.solver.lm_max_iterations)
        iters += it
        v, kept, it = tls_descent(base, built.subset(trial), v, c2[trial], params, params.robust.kernel_descent_rounds)
        iters += it
        new = np.zeros_like(inlier)
        new[np.flatnonzero(trial)[kept]] = True
        if not (new & member).any():
            continue
        # the kept clusters the descent dropped loops from are judged as one hypothesis each, as in the group test
        kept_component = revisits(data, window, inlier)
        lost = inlier & ~new
        groups = [member] + [kept_component == h for h in np.unique(kept_component[lost]).tolist()]
        charged = [(m, group_threshold(prob[m], dof, scale, params)) for m in groups]
        f0 = group_objective(base_graph, built, values, c2, charged)
        f = group_objective(base_graph, built, v, c2, charged)
        if f < f0:
            notes.append(f"retry: a rejected cluster of {int(member.sum())} loops back with {int((new & member).sum())}"
                         f" kept, {int(lost.sum())} kept loops out; objective {f0:.6g} -> {f:.6g}")
            values, inlier = v, new
            known = kept_factors(inlier)
            added += 1
    notes.append(f"retry: {added} of {len(order)} tried clusters rejected whole kept ({len(whole)} such clusters; "
                 f"{skipped} dropped on the marginal of the solved map)")
    return values, inlier, iters
