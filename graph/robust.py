"""The robust batch solve: local consistency, then graduated non-convexity over clusters of loops.

1. support (`graph.support`): loops agreeing with a nearby loop over a short odometry cycle are grouped into
   clusters (connected components); a loop without support is its own cluster. Drift does not enter this test.
2. start: least squares on odometry + the supported loops, initialised by LAGO (2D) / chordal (3D) on that subset,
   so the start already carries the loop corrections however large the drift was (a start from the drifted
   odometry chain makes every true loop look like an outlier: ring, 8 m of drift). When some supported loop does
   not fit there, also GNC from the odometry chain, and when the two GNC starts keep different loops a
   DCS-kernel solve + TLS descent (graph.kernel_start); the lowest TLS objective wins. Where a solve over every
   candidate fills in (long-range groups of consistent false loops), the clusters are decided on a reduced graph
   instead of those GNC starts (graph.cluster_start).
3. GNC with truncated least squares (Yang et al. 2020), odometry and anchor as known inliers, one weight per
   loop. Inner solves are warm-started (a few LM iterations per step).
4. polish with the kept loops; the group-level test (each kept revisit cluster one TLS term at the chi-square
   quantile of its n x dof, dropped when the objective is lower without it, those nearest their thresholds first:
   a group of mutually consistent false loops is one hypothesis the rest of the map accepts or rejects as a
   whole); the clusters some start rejected whole, out at once and offered back one by one (graph.disputed);
   then re-admit every rejected loop that fits its own threshold at the solution.
   Then the short-tail screen (`_short_tail_screen`): the kept short-span loops are judged at the kept loops' tail
   margin on the map re-solved without them, where a false loop that bent its few steps of odometry no longer fits
   (at the family-wise bound of the kept loops instead where they follow the calibrated model; each dropped revisit
   offered back by a solve over its neighbourhood, graph.local_solve).
   Then the own-cycle test (graph.short_span): a kept loop between nodes a few steps apart whose cycle with the
   odometry between its ends is worse than the agreeing cycles of the kept loops is dropped.
5. once the loop set is decided, Gauss-Newton steps on the kept loops until the map stops moving (graph.polish):
   LM's cost tolerance stops far from the optimum on a flat objective (w10000: 0.56 m).

This module holds the problem (`ConsensusProblem`) and the order of the steps (`decide`); the pieces live apart:
graph.support (step 1), graph.calibration, graph.tls (TLS objective, GNC), graph.kernel_start, graph.groups (the
group test), graph.readmit, graph.polish.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import gtsam
import numpy as np
from scipy.stats import chi2

from graph.batch import BuiltGraph, build, initial_guess, resolve_init, solve_lm
from graph.calibration import VarianceFactors, refined_factor, scale_information, split_factors
from graph.cluster_start import cluster_starts
from graph.confident import confident_first, confident_holds, confident_start, confident_whole, whole_misfit_share
from graph.disputed import judge_disputed
from graph.factors import array_from_values, graph_of, values_from_array
from graph.groups import drop_false_groups, group_threshold, retry_rejected
from graph.kernel_start import dcs_solve, tls_descent
from graph.linear import costly, narrow, solver_scope
from graph.local_solve import local_solve, neighbourhood
from graph.model import TANGENT_DIM, PoseGraphData
from graph.params import GraphParams, InitMethod
from graph.polish import polish
from graph.readmit import readmit_dropped, readmit_supported
from graph.reduced import reduced_gnc
from graph.result import GraphResult
from graph.short_span import own_cycle_veto
from graph.support import CycleSupport, cycle_support, revisits
from graph.thresholds import base_threshold, family_bound, heavy_tailed, loop_thresholds, short_span, tail_margin
from graph.tls import admit_fitting, gnc_tls, tls_objective

__all__ = ["ConsensusProblem", "decide", "group_threshold", "gnc_tls", "robust_solve", "tls_objective"]


@dataclass
class ConsensusProblem:
    """What the decision (steps 2-4) works on: the graph on the model it judges by, its candidates and starts."""
    data: PoseGraphData
    stated: BuiltGraph          # the stated information: final polish and reported residuals
    built: BuiltGraph           # the information the loops are judged on (calibrated in 3D with the split)
    pairs: tuple                # agreeing loop pairs of the cycle test (graph.support)
    cand: np.ndarray            # loops GNC judges: the supported ones (the rest go to the trial)
    odometry_values: gtsam.Values
    method: InitMethod          # the LAGO / chordal initialisation
    params: GraphParams
    notes: list[str]
    starts: list[tuple[str, gtsam.Values]] = field(default_factory=list)
    scale: float = 1.0          # the thresholds' calibration scale (margin x variance factor)
    sigma0: float = 1.0         # the scalar variance factor (1 when uncalibrated or split)
    cycles: CycleSupport | None = None      # the agreeing cycles (graph.short_span reads their tail)
    factors: VarianceFactors | None = None  # split 3D variance factors, when the loops are judged calibrated
    confident: tuple | None = None   # (cluster label or -1, start thunk) of the confidently supported loops (graph.confident)
    pending: Callable[[], None] | None = None    # makes `starts` when called (deferred behind the confident start)

    def __post_init__(self):
        self.base = self.built.priors + self.built.odometry       # known inliers
        self.base_graph = graph_of(self.base)

    @property
    def loops(self) -> int:
        return len(self.built.loops)

    @cached_property
    def loop_ends(self) -> tuple[np.ndarray, np.ndarray]:
        """Node indices of each loop's two ends, in loop order."""
        idx = self.built.loop_idx
        return self.built.a[idx], self.built.b[idx]

    @cached_property
    def short(self) -> np.ndarray:
        """Per loop: whether it spans at most the short span (graph.thresholds.short_span)."""
        a, b = self.loop_ends
        return short_span(np.abs(a - b), self.params.robust.support_window)

    def ready(self) -> None:
        """Make the deferred starts."""
        if self.pending is not None:
            self.pending, make = None, self.pending
            make()

    def objective(self, values: gtsam.Values, c2: np.ndarray) -> float:
        return tls_objective(self.base_graph, self.built, values, c2)

    def lm(self, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, iterations: int):
        return solve_lm(graph, values, self.params, iterations)


def _prepare(data: PoseGraphData, params: GraphParams) -> tuple[ConsensusProblem, np.ndarray]:
    """Steps 1-2: the cycle test, the noise calibration and the starts; returns the problem and its thresholds."""
    stated = build(data, params.replace(robust="none"))
    dof = TANGENT_DIM[data.dim]
    notes: list[str] = []
    # 1. local consistency
    split = params.robust.calibrate_noise and params.robust.calibration_split and data.dim == 3
    cycles = cycle_support(data, params.robust.support_window,
                           float(chi2.ppf(params.robust.support_probability, dof)),
                           decompose=params.robust.calibration_propagate if split else 0)
    pairs = cycles.pairs
    calibrate = params.robust.calibrate_noise and len(pairs[2]) >= params.robust.calibration_min_loops
    factors = split_factors(cycles) if (calibrate and split) else None
    if factors is not None:
        # the robust solve runs on the calibrated model (its thresholds carry no variance factor); the final polish
        # and the reported residuals are on the stated information
        built = build(scale_information(data, factors), params.replace(robust="none"))
    else:
        built = stated
    L = len(built.loops)
    supported = np.zeros(L, bool)
    supported[pairs[0]] = True
    supported[pairs[1]] = True
    # GNC over the supported loops only: an unsupported loop is tested once the map is solved (step 4). This keeps
    # random long-range loops out of every inner solve (their fill-in is what makes a joint solve slow)
    cand = supported if params.robust.support_window > 0 else np.ones(L, bool)
    method = resolve_init(data, params.replace(robust="none"))     # AUTO: LAGO (2D) / chordal (3D)
    # every solve of the starts holds candidates only: one fill-in estimate for all of them (graph.linear)
    with narrow(lambda: built.pairs(cand)):
        # 2. starts: least squares on the supported loops from LAGO / chordal; the odometry chain
        odometry_values = values_from_array(data.dim, initial_guess(data, stated, InitMethod.ODOMETRY))
        cs = ConsensusProblem(data, stated, built, pairs, cand, odometry_values, method, params, notes,
                              cycles=cycles, factors=factors)

    def supported_start() -> None:
        if not (supported.any() or method == InitMethod.GIVEN):
            return
        with narrow(lambda: built.pairs(cand)):
            try:
                # the LAGO / chordal guess from the stated information: it is only a start, and the calibrated one
                # can be too ill-conditioned for the chordal relaxation (garage: rotation 500x tighter than
                # translation)
                guess = initial_guess(data, stated.subset(supported), method)
                # only a start: GNC continues from it (a converged solve here cost 60 s on city10000 at 50 %)
                v, _ = cs.lm(built.graph(supported), values_from_array(data.dim, guess),
                             params.robust.consensus_inner_iterations)
                cs.starts.append(("supported loops", v))
            except RuntimeError:
                notes.append("LAGO / chordal start on the supported loops failed")
    c2 = loop_thresholds(data.probability[built.loop_idx], dof, params)
    if factors is not None:
        # the information is calibrated already (graph.calibration): only the heavy-tail margin is left
        cs.scale = params.robust.calibration_margin
        notes.append(f"variance factors translation {factors.translation:.3g}, rotation {factors.rotation:.3g} "
                     f"(one factor: {factors.scalar:.3g}): thresholds x {cs.scale:.3g} on the calibrated information")
    elif calibrate:
        # variance factor from the agreeing cycles: their median error over the chi-square median. Local, so
        # neither drift nor a false loop bending the map (both inflate a global a-posteriori estimate) enter it
        cs.sigma0 = refined_factor(cycles, dof, float(chi2.ppf(params.robust.support_probability, dof))
                                   * params.robust.calibration_margin, params.robust.calibration_refine)
        cs.scale = params.robust.calibration_margin * cs.sigma0
        notes.append(f"variance factor {cs.sigma0:.3g}: thresholds x {cs.scale:.3g}")
    cs.confident = confident_start(cs, supported)
    # with a confident start the supported one is made only when needed: on w10000 at 50 % random its LAGO and LM
    # factor thousands of chance-supported long-range false loops (127 s of 142 s) and the confident start stands
    # alone (graph.confident)
    if cs.confident is None:
        supported_start()
    else:
        cs.pending = supported_start
    return cs, c2 * cs.scale


@dataclass
class _Best:
    """The start with the lowest TLS objective so far."""
    objective: float = np.inf
    values: gtsam.Values | None = None
    inlier: np.ndarray | None = None
    untouched: bool = False      # GNC took no step and kept every candidate: local consensus = global solution
    iterations: int = 0
    kept: list[np.ndarray] = field(default_factory=list)     # the loops each start kept (graph.disputed)


def _run_start(cs: ConsensusProblem, c2: np.ndarray, name: str, v0: gtsam.Values, best: _Best,
               descent: bool = False) -> np.ndarray:
    """GNC (or, for the kernel start, TLS descent: no convex surrogate) over the candidates from `v0`; updates
    `best`; returns the loops it kept."""
    cand = cs.cand
    sub = cs.built.subset(cand)
    if descent:
        values, kept, outer = tls_descent(cs.base, sub, v0, c2[cand], cs.params, cs.params.robust.kernel_descent_rounds)
    else:
        values, kept, outer, it = gnc_tls(cs.base, sub, v0, c2[cand], np.arange(int(cand.sum())), cs.params)
        best.iterations += it
    inlier = np.zeros(cs.loops, bool)
    inlier[cand] = kept
    best.kept.append(inlier)
    f = tls_objective(cs.base_graph, sub, values, c2[cand])
    cs.notes.append(f"start {name}: {'TLS descent' if descent else 'GNC'} {outer} steps, TLS objective {f:.6g}, "
                    f"{int(kept.sum())} loops kept")
    if best.values is None or f < best.objective:
        best.objective, best.values, best.inlier = f, values, inlier
        best.untouched = outer == 0 and bool(kept.all())
    return inlier


def _best_start(cs: ConsensusProblem, c2: np.ndarray) -> _Best:
    """Steps 2-3: GNC from each start, the lowest TLS objective wins."""
    best = _Best()
    # chance-supported random false loops bend every GNC start: first a TLS descent from the map of the confident
    # loops alone, the only start when every confident cluster keeps loops there (graph.confident)
    if (cs.confident is not None and cs.params.robust.cluster_start
            and costly(lambda: cs.built.pairs(cs.cand))):
        _costly_starts(cs, c2, best)
    else:
        conf_first = confident_first(cs, c2)
        share = whole_misfit_share(cs, c2) if conf_first else 0.0
        if share > cs.params.robust.confident_misfit_max_share:
            # as on the costly path: many confident clusters misfit whole at the confident map, so groups of
            # consistent false loops among the confident ones bent it; that start cannot stand alone, and its
            # descent creeps (city10000 at 50 % local-grouped: 10 re-solves, 118 s of 167 s, and the supported
            # start won by the TLS objective, 23295 against 26163)
            cs.notes.append(f"confident start skipped: {share:.3g} of the confident clusters misfit whole at the "
                            "confident map")
            cs.ready()
            _gnc_starts(cs, c2, best, confident_after=False)
        elif conf_first and confident_holds(cs, _run_start(cs, c2, "confident loops", cs.confident[1](), best,
                                                           descent=True)):
            cs.notes.append("GNC starts skipped: every confident cluster keeps loops at the confident start")
        else:
            cs.ready()
            _gnc_starts(cs, c2, best, confident_after=not conf_first)
    return best


def _costly_starts(cs: ConsensusProblem, c2: np.ndarray, best: _Best) -> None:
    """The starts where a solve over every candidate fills in (its direct factorisation estimated above
    `solver.direct_max_cost`; `cluster_start`): the confident start as elsewhere while it can stand alone, else the
    clusters decided on the reduced graph (`_cluster_starts`) instead of the GNC starts over every candidate."""
    if costly(lambda: cs.built.pairs(cs.confident[0] >= 0)):
        # the confident loops fill in themselves: they hold many long-range groups that agree among themselves, so
        # their map is no start free of false loops, and its LAGO / chordal factors them all (w10000 at 50 %
        # random-grouped: ~1e12 estimated flops, no result in 4 minutes)
        cs.notes.append("confident start skipped: the confident loops fill in")
        _cluster_starts(cs, c2, best)
    elif not confident_first(cs, c2):
        # every candidate fits at the confident map (clean graphs): the supported start fits too
        cs.ready()
        _gnc_starts(cs, c2, best, confident_after=True)
    elif not confident_whole(cs, c2):
        # a confident cluster misfits whole at the confident map: the descent from there would reject it whole (a
        # group of consistent false loops among the confident ones bent that map), so that start cannot stand
        # alone, and the descent creeps for minutes on such a graph (city10000 at 50 % random-grouped: 90 s)
        cs.notes.append("confident start skipped: a confident cluster misfits whole at the confident map")
        _cluster_starts(cs, c2, best)
    elif not confident_holds(cs, _run_start(cs, c2, "confident loops", cs.confident[1](), best, descent=True)):
        _cluster_starts(cs, c2, best)
    else:
        cs.notes.append("GNC starts skipped: every confident cluster keeps loops at the confident start")


def _cluster_starts(cs: ConsensusProblem, c2: np.ndarray, best: _Best) -> None:
    """The GNC starts over every candidate would factor the false groups among them (fill-in: minutes on 10^4
    nodes): the clusters are decided on the reduced graph instead (graph.cluster_start); from each decision, GNC over
    the loops of its kept clusters, then TLS descent over every candidate (the rejected groups misfit there and are
    never factored)."""
    for name, v0, members in cluster_starts(cs, c2):
        with narrow(lambda: cs.built.pairs(members)):
            v, kept, outer, it = gnc_tls(cs.base, cs.built.subset(members), v0, c2[members],
                                         np.arange(int(members.sum())), cs.params)
        best.iterations += it
        cs.notes.append(f"{name}: GNC over the loops of the kept clusters {outer} steps, {int(kept.sum())} of "
                        f"{int(members.sum())} kept")
        _run_start(cs, c2, name, v, best, descent=True)


def _gnc_starts(cs: ConsensusProblem, c2: np.ndarray, best: _Best, confident_after: bool) -> None:
    """GNC from the supported start, then (when some supported loop misfits there) from the odometry chain, the
    DCS kernel when those two disagree, and the confident start when it did not run first (`confident_after`)."""
    for name, v0 in cs.starts:
        _run_start(cs, c2, name, v0, best)
    robust = cs.params.robust
    if not (best.values is None or (robust.odometry_start and not best.untouched)):
        cs.notes.append("odometry start skipped: every supported loop fits at the supported start")
        return
    # the odometry start exists for one failure: a group of mutually consistent false loops in the supported
    # set bends the supported start, and the GNC from there keeps the group and rejects the loops it strains
    # (ring, CSAIL). When every supported loop already fits its threshold at the supported start (no GNC step:
    # the local consensus and the global solution agree), no loop is truncated and that failure cannot have
    # happened; the second start (the slowest solve: drift makes its GNC start near-convex) is skipped.
    # (A weaker sign, a cluster of agreeing loops split by the solution, misses ring random-grouped.)
    first = best.inlier
    if robust.odometry_start_short_skip and first is not None and not _long_rejected(cs, first):
        # the failure that start exists for truncates the loops a bent map strains, and a bend is map-scale: over a
        # short span the odometry and the loops nearby fix the relative pose (graph.thresholds.short_span). When
        # every candidate the supported start rejected is short-span, every long-range candidate is kept and none
        # was strained (city10000 at 50 % local-grouped: 17 GNC steps from the odometry chain, 21 s of 167 s, to
        # the same loops and TLS objective)
        cs.notes.append("odometry start skipped: every candidate the supported start rejected is short-span")
        if cs.confident is not None and confident_after:
            _run_start(cs, c2, "confident loops", cs.confident[1](), best, descent=True)
        return
    agree = first is not None and np.array_equal(first, _run_start(cs, c2, "odometry", cs.odometry_values, best))
    if robust.kernel_start and not agree:
        # groups of consistent false loops spread over the map bend GNC's convex surrogate itself, from either
        # start (manhattan random-grouped): a DCS solve from the odometry chain never forms it
        v0 = dcs_solve(cs.base, cs.built.subset(cs.cand).loops, cs.odometry_values,
                       robust.kernel_phi * cs.sigma0, cs.params)
        _run_start(cs, c2, "DCS kernel", v0, best, descent=True)
    elif robust.kernel_start:
        # a surrogate bent by false groups traps each GNC in a minimum of its own start (manhattan random-
        # grouped: 1700 and 1777 loops kept from the two starts); two starts as far apart as the LAGO map of the
        # supported loops and the raw odometry chain ending at the same loops is the sign it did not
        cs.notes.append("DCS-kernel start skipped: both GNC starts kept the same loops")
    if cs.confident is not None and confident_after:
        _run_start(cs, c2, "confident loops", cs.confident[1](), best, descent=True)


def _long_rejected(cs: ConsensusProblem, inlier: np.ndarray) -> bool:
    """Whether some candidate rejected in `inlier` spans more than the short span (graph.thresholds.short_span)."""
    return bool(np.any(cs.cand & ~inlier & ~cs.short))


def _try_unsupported(cs: ConsensusProblem, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray
                     ) -> tuple[gtsam.Values, np.ndarray, int]:
    """Step 4, the unsupported loops closest to fitting, tried jointly by a GNC that includes them."""
    built, params, iters = cs.built, cs.params, 0
    trial = ~cs.cand & ~inlier
    if trial.sum() > params.robust.trial_max_loops:
        # the ones nearest to their threshold at the solution, within `readmit_factor` of it: a lone true loop
        # closing a long drift misses it by a few times (manhattan: r^2 18 against 3.3, 0.002 once kept); a random
        # false loop by orders of magnitude, and long-range false loops in every inner solve cost minutes on
        # 10^4-node graphs (fill-in). With few unsupported loops all are tried (ring: 8 m of drift)
        ratio = np.where(trial, built.r2(values) / c2, np.inf)
        ratio[ratio > params.robust.readmit_factor] = np.inf
        trial = np.zeros(cs.loops, bool)
        trial[np.argsort(ratio, kind="stable")[:params.robust.trial_max_loops]] = True
        trial &= np.isfinite(ratio)
    if trial.any() and params.robust.trial_forecast:
        # the trial's GNC on the marginal of the solved map on the tried loops' ends (graph.reduced): when it keeps
        # none, the whole-graph GNC is not run (w10000 at 50 % random: ~13 whole-graph solves that keep none)
        known = cs.base + [f for f, k in zip(built.loops, inlier.tolist()) if k]
        idx = np.flatnonzero(trial)
        try:
            forecast = reduced_gnc(known, values, [built.loops[i] for i in idx], c2[idx], cs.data.dim, params)
        except RuntimeError:          # an indeterminate marginal: no forecast, the trial runs
            forecast = np.ones(len(idx), bool)
        if not forecast.any():
            cs.notes.append(f"trial: none of {len(idx)} unsupported loops kept on the marginal of the solved map")
            trial[:] = False
    if not trial.any():
        return values, inlier, 0
    # judged by a GNC that includes them, so the map can move to them; a test at a solution without them would
    # see the drift as their residual
    pool = inlier | trial
    sub = built.subset(pool)
    with narrow(lambda: built.pairs(pool)):
        v, kept, outer, it = gnc_tls(cs.base, sub, values, c2[pool], np.arange(int(pool.sum())), params)
    iters += it
    new_inlier = np.zeros(cs.loops, bool)
    new_inlier[pool] = kept
    if cs.objective(v, c2) <= cs.objective(values, c2):
        # the trial may push out a loop kept so far (a false trial loop pulls through GNC's surrogate): one joint
        # re-solve with those back (graph.readmit)
        with narrow(lambda: built.pairs(pool)):
            v, new_inlier, it = readmit_dropped(built, v, new_inlier, inlier, c2, lambda x: cs.objective(x, c2),
                                                cs.lm, params, cs.notes)
        iters += it
        values, inlier = v, new_inlier
        cs.notes.append(f"{int(trial.sum())} unsupported loops tried jointly: {int((kept & trial[pool]).sum())} kept")
    values, inlier, it = admit_fitting(built, values, inlier, c2, params, cs.notes)
    return values, inlier, iters + it


def _readmit_agreeing(cs: ConsensusProblem, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray
                      ) -> tuple[gtsam.Values, np.ndarray, int]:
    """A rejected loop that agrees with a kept one may fit only once it is in (graph.readmit). With
    `readmit_short_tail`, short-span loops are judged there at the kept loops' own tail margin (`_short_tail`)."""
    built = cs.built
    p = cs.params.robust
    if p.readmit_short_tail and cs.scale != 1.0:
        # the re-admission overturns a rejection on the strength of agreement alone; a false loop a few steps beside
        # a true revisit agrees with it and fits once in, within the global margin (manhattan local 50 %, seeds
        # 1-3: every loop it re-admitted, 0.2-0.4x the threshold, 1.3-2.4x at the tail margin). Over a short span
        # no drift strain excuses a misfit
        c2 = _short_tail(cs, values, inlier, c2)[0]

    # its steps re-weight at most `readmit_max_loops` candidates against a fixed map: iSAM2's case (graph.tls)
    isam2 = p.readmit_isam2_steps and cs.data.dim == 2
    gauss_newton = isam2 and p.readmit_isam2_gauss_newton

    def judge(mask: np.ndarray, v0: gtsam.Values):
        # GNC over the candidates only; odometry, anchor and the kept loops are known inliers
        known = cs.base + [f for f, k in zip(built.loops, inlier.tolist()) if k]
        v, ok, _, n = gnc_tls(known, built.subset(mask), v0, c2[mask], np.arange(int(mask.sum())), cs.params,
                               gauss_newton, final_solve=False, isam2_steps=isam2)
        out = np.zeros(cs.loops, bool)
        out[np.flatnonzero(mask)[ok]] = True
        return v, out, n

    return readmit_supported(built, values, inlier, cs.pairs[0], cs.pairs[1], c2, lambda x: cs.objective(x, c2),
                             cs.lm, judge, cs.params, cs.notes)


def decide(cs: ConsensusProblem, c2: np.ndarray) -> tuple[gtsam.Values, np.ndarray, int, float]:
    """Steps 2-4 with thresholds c2: (values, inlier, LM iterations, end of the GNC stage)."""
    # every solve of the starts holds candidates only: one fill-in estimate for all of them (graph.linear)
    with narrow(lambda: cs.built.pairs(cs.cand)):
        best = _best_start(cs, c2)
    values, inlier, iters = best.values, best.inlier, best.iterations
    t_gnc = time.perf_counter()
    # 4. polish; admit the loops that fit at the solution; try the unsupported loops closest to fitting jointly.
    # The polish and the group test solve the kept loops or fewer: one fill-in estimate for both (graph.linear)
    kept = inlier
    with narrow(lambda: cs.built.pairs(kept)):
        values, it = cs.lm(cs.built.graph(inlier), values, cs.params.solver.lm_max_iterations)
        iters += it
        values, inlier, it = drop_false_groups(cs.data, cs.built, cs.base_graph, values, inlier, c2, cs.scale,
                                               cs.method, cs.params, cs.notes, cs.stated)
    iters += it
    values, inlier, it = judge_disputed(cs.data, cs.built, cs.base_graph, values, inlier, c2, cs.scale, cs.method,
                                        cs.params, cs.notes, best.kept, cs.stated)
    iters += it
    values, inlier, it = retry_rejected(cs.data, cs.built, cs.base_graph, values, inlier, cs.cand, c2, cs.scale,
                                        cs.params, cs.notes)
    iters += it
    values, inlier, it = admit_fitting(cs.built, values, inlier, c2, cs.params, cs.notes)
    iters += it
    values, inlier, it = _try_unsupported(cs, values, inlier, c2)
    iters += it
    values, inlier, it = _readmit_agreeing(cs, values, inlier, c2)
    return values, inlier, iters + it, t_gnc


def _short_tail(cs: ConsensusProblem, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray
                ) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """(thresholds with the tail margin (graph.thresholds.tail_margin) of the kept loops at `values` on the
    short-span loops (graph.thresholds.short_span), the others as `c2`; the margin; the short-span mask; r^2)."""
    short = cs.short
    r2 = cs.built.r2(values)
    margin = tail_margin(r2[inlier], cs.sigma0, TANGENT_DIM[cs.data.dim], cs.params)
    return np.where(short, c2 * (margin * cs.sigma0 / cs.scale), c2), margin, short, r2


def _short_tail_screen(cs: ConsensusProblem, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray
                       ) -> tuple[gtsam.Values, np.ndarray, int]:
    """The kept short-span loops judged on the map unbent by them: all left out at once and re-solved (the long
    loops and the odometry hold the map), then taken back by TLS descent at the tail margin (`_short_tail`); the
    new set stands when the TLS objective at those thresholds is not higher than the decision's.

    A false loop kept from the start (the confident start's descent) has bent its few steps of odometry until it
    fits even the tail margin (manhattan local-grouped 50 %: 0.2-0.8x), so no test at the solution sees it; with
    the short-span loops out the odometry between its ends is straight again and it sits far outside (8-18x, the
    true short-span loops there at most 0.12x). Over a short span the odometry and the loops nearby fix the
    relative pose, so leaving them all out at once does not free the map where a true one is needed."""
    tight, margin, short, r2 = _short_tail(cs, values, inlier, c2)
    judged = inlier & short
    if cs.params.robust.screen_family_bound:
        tight, margin = _family_tight(cs, r2, inlier, short, tight, margin)
    if not judged.any() or margin >= cs.params.robust.calibration_margin:
        return values, inlier, 0
    # every solve of the screen holds kept loops only: one fill-in estimate for all (graph.linear)
    with narrow(lambda: cs.built.pairs(inlier)):
        return _screen_short(cs, values, inlier, judged, tight, margin)


def _family_tight(cs: ConsensusProblem, r2: np.ndarray, inlier: np.ndarray, short: np.ndarray, tight: np.ndarray,
                  margin: float) -> tuple[np.ndarray, float]:
    """(thresholds, margin) of the short-tail screen with the family-wise bound of the n kept loops
    (graph.thresholds.family_bound: chi-square^-1(1 - (1 - p) / n) x the variance factor, p = `inlier_probability`)
    on the short-span loops where it is tighter than the tail margin, and only where the kept loops follow the
    calibrated model (at most a share 1 - p of them above its chi-square p quantile: graph.thresholds.heavy_tailed).

    The tail margin is `fence_factor` x a high quantile of the kept loops' r^2: generous by design, since it must
    hold the heaviest true tail of any graph. Where the kept loops follow the calibrated model, n true loops exceed
    the family-wise bound with probability at most 1 - p, so a short-span loop above it on the map unbent by the
    short-span loops is no true loop of that model (w10000 at 50 % local, seed 2: 224 injected loops kept, 0.3 m
    claims between poses 2 cm apart, at a median 3.7x chi-square(0.99) calibrated at the clean optimum, 132 of them
    above the bound of 3.0x there; its 54312 true loops reach 1.9x)."""
    dof = TANGENT_DIM[cs.data.dim]
    prob = cs.params.robust.inlier_probability
    unit = cs.sigma0
    if not inlier.any() or heavy_tailed(r2[inlier] / unit, dof, prob):
        return tight, margin
    bound = family_bound(int(inlier.sum()), dof, prob)
    out = np.where(short, np.minimum(tight, bound * unit), tight)
    return out, min(margin, bound / base_threshold(dof, cs.params))


def _screen_short(cs: ConsensusProblem, values: gtsam.Values, inlier: np.ndarray, judged: np.ndarray,
                  tight: np.ndarray, margin: float) -> tuple[gtsam.Values, np.ndarray, int]:
    """`_short_tail_screen` once its short-span loops (`judged`) and their thresholds (`tight`) are known."""
    rest = inlier & ~judged
    v0, iters = cs.lm(cs.built.graph(rest), values, cs.params.solver.lm_max_iterations)
    if np.all(cs.built.r2(v0)[judged] <= tight[judged]):
        return values, inlier, iters
    known = cs.base + [f for f, k in zip(cs.built.loops, rest.tolist()) if k]
    v, kept, n = tls_descent(known, cs.built.subset(judged), v0, tight[judged], cs.params,
                             cs.params.robust.kernel_descent_rounds)
    iters += n
    new = rest.copy()
    new[np.flatnonzero(judged)[kept]] = True
    # the descent only drops: a loop left out with its duplicates misfits the unbent map and the re-solve without
    # it does not bend back (manhattan: two true loops 3371 -> 3383, 0.01x the tail margin kept, 1.5x unbent). Each
    # revisit of dropped loops is offered back as one claim: kept when all of it fits and the objective is not higher
    f1 = cs.objective(v, tight)
    lost = inlier & ~new
    window = cs.params.robust.support_window
    component = revisits(cs.data, window, lost)
    back = 0
    ends_a, ends_b = cs.loop_ends
    for g in np.unique(component[lost]).tolist():
        member = component == g
        # a short-span revisit moves only its own stretch and neighbourhood (graph.local_solve): the rest is held
        free = (neighbourhood(cs.data.num_nodes, ends_a[member], ends_b[member], window)
                if cs.params.robust.screen_local else None)
        # all back, then the misfits leave (a true loop beside a false group shares its revisit)
        for _ in range(cs.params.robust.kernel_descent_rounds):
            if free is None:
                v2, it = cs.lm(cs.built.graph(new | member), v, cs.params.solver.lm_max_iterations)
            else:
                v2, it = local_solve(cs.built, new | member, v, free, cs.data.dim, cs.params,
                                     cs.params.solver.lm_max_iterations)
            iters += it
            fit = member & (cs.built.r2(v2) <= tight)
            if np.array_equal(fit, member):
                break
            member = fit
        if member.any() and np.array_equal(fit, member):
            f2 = cs.objective(v2, tight)
            if f2 <= f1:
                v, new, f1 = v2, new | member, f2
                back += int(member.sum())
    f0 = cs.objective(values, tight)
    dropped = int((inlier & ~new).sum())
    cs.notes.append(f"short-tail screen: {dropped + back} of {int(judged.sum())} kept short-span loops misfit the "
                    f"tail margin {margin:.3g} once unbent, {back} fit again once back; TLS objective {f0:.6g} -> "
                    f"{f1:.6g}")
    if f1 > f0:
        return values, inlier, iters
    return v, new, iters


def _own_cycle_test(cs: ConsensusProblem, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray
                    ) -> tuple[gtsam.Values, np.ndarray, int]:
    """Drop the kept short-span loops that fail their own-cycle test (graph.short_span) and re-solve on the rest."""
    p = cs.params.robust
    drop, note = own_cycle_veto(cs.data, cs.cycles, cs.factors, inlier, c2, c2 / (cs.scale / cs.sigma0),
                                p.own_cycle_quantile, p.support_window, p.calibration_min_loops)
    if note is not None:
        cs.notes.append(note)
    if not drop.any():
        return values, inlier, 0
    inlier = inlier & ~drop
    values, it = cs.lm(cs.built.graph(inlier), values, cs.params.solver.lm_max_iterations)
    return values, inlier, it


def robust_solve(data: PoseGraphData, params: GraphParams) -> GraphResult:
    """The consensus solve (module doc); every LM call in it picks its linear solver by fill-in (graph.linear)."""
    a, b = data.edge_index_pairs()
    with solver_scope(lambda: np.column_stack([a, b]), data.dim, params):
        return _robust_solve(data, params)


def _robust_solve(data: PoseGraphData, params: GraphParams) -> GraphResult:
    t_start = time.perf_counter()
    cs, c2 = _prepare(data, params)
    t_decide = time.perf_counter()
    init_seconds = t_decide - t_start
    stated, notes = cs.stated, cs.notes
    initial_cost = float(stated.graph().error(cs.odometry_values))
    values, inlier, iters, t_gnc = decide(cs, c2)
    if params.robust.short_tail_screen and cs.scale != 1.0:
        values, inlier, it = _short_tail_screen(cs, values, inlier, c2)
        iters += it
    if params.robust.own_cycle_test and cs.scale != 1.0:
        values, inlier, it = _own_cycle_test(cs, values, inlier, c2)
        iters += it
    t_polish = time.perf_counter()
    # 5. the loop set is decided: converge the map on it (graph.polish; LM stopped at its cost tolerance)
    values, it, why = polish(stated.graph(inlier), values, data.dim, params)
    iters += it
    t_end = time.perf_counter()
    notes.append(f"polish: {it} Gauss-Newton steps ({why})")
    notes.append(f"stages: support+starts {init_seconds:.2f} s, GNC {t_gnc - t_decide:.2f} s, "
                 f"trial+readmit {t_polish - t_gnc:.2f} s, polish {t_end - t_polish:.2f} s")
    r2 = stated.r2(values)
    final_cost = float(stated.graph(inlier).error(values))
    supported = np.zeros(cs.loops, bool)     # a mask, not np.union1d: a sort of 10^6 pairs for one count
    supported[cs.pairs[0]] = True
    supported[cs.pairs[1]] = True
    notes.append(f"support: {int(supported.sum())} of {cs.loops} loops")
    poses = array_from_values(data.dim, values, data.num_nodes)
    return GraphResult(data.dim, data.node_ids.copy(), poses, cs.built.loop_idx, inlier, inlier.astype(float), r2,
                       initial_cost, final_cost, iters, t_end - t_start, init_seconds, params.solver.method.value,
                       params.robust.method.value, cs.method.value, 0, notes)
