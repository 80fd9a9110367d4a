"""Re-admission of loops the joint trial of the unsupported loops dropped (step 4 of graph.robust).

The unsupported loops are judged by a GNC over them and every loop kept so far, started from the solution, so
the map can move to a lone true loop. That GNC starts from its convex surrogate, where a false loop among the
tried ones still pulls on the map; it may push out a loop the consensus and the group test had kept, and once
the false loop is truncated the GNC ends in a minimum without it (intel, 10 % random, seed 2: loops 667 and 669
of 785 true, kept by the consensus, r^2 0.6 against a threshold of 1.55 at the clean optimum, 3.7 and 4.1 at the
trial's result; the map 4.9 mm ATE from the clean optimum). The trial was there to judge the unsupported loops,
not to revisit the decided ones, so each loop it dropped gets one joint re-solve: all of them back, LM from the
trial's solution, kept when every one of them fits its own threshold there and the TLS objective is not higher.
Nothing new enters the candidate set (only loops that had passed the consensus and the group test), so a false
loop is re-admitted only if it had already been kept before the trial.
"""
from __future__ import annotations

from typing import Callable

import gtsam
import numpy as np

from graph.linear import narrow
from graph.params import GraphParams


def readmit_dropped(built, values: gtsam.Values, inlier: np.ndarray, before: np.ndarray, c2: np.ndarray,
                    objective: Callable[[gtsam.Values], float], solve: Callable, params: GraphParams,
                    notes: list[str]) -> tuple[gtsam.Values, np.ndarray, int]:
    """(values, inlier, LM iterations) after one joint re-solve with the loops kept `before` the trial and not in
    `inlier` now; `solve(graph, values, iterations)` -> (values, iterations) is the LM of the caller, `objective`
    its TLS objective over every loop."""
    lost = before & ~inlier
    if not lost.any():
        return values, inlier, 0
    trial = inlier | lost
    v, it = solve(built.graph(trial), values, params.solver.lm_max_iterations)
    fits = bool(np.all(built.r2(v)[lost] <= c2[lost]))
    if fits and objective(v) <= objective(values):
        notes.append(f"re-admitted {int(lost.sum())} loops the joint trial had dropped (they fit once back)")
        return v, trial, it
    notes.append(f"{int(lost.sum())} loops dropped by the joint trial stay out (misfit or higher objective)")
    return values, inlier, it


def nearest_candidates(r2: np.ndarray, c2: np.ndarray, cand: np.ndarray, factor: float, limit: int) -> np.ndarray:
    """The loops of `cand` within `factor` of their threshold (r2 <= factor x c2) and, of those, the `limit` nearest
    to it (smallest r2 / c2, ties by index; `limit` 0: no cap). A loop that fits only once it is back misses by a
    few times at the solution (intel 667 and 669: 2.35x and 2.65x); a chance-supported false loop beside a true
    revisit on a 10^4-node graph by 10-1800x (w10000 at 50 % random: 728 candidates, one re-admitted at 1.15x), and
    each of those in the re-solve is long-range fill-in and strain the LM fights for tens of iterations."""
    ratio = np.where(cand, r2 / c2, np.inf)
    ratio[ratio > factor] = np.inf
    out = np.isfinite(ratio)
    if limit > 0 and int(out.sum()) > limit:
        out = np.zeros(len(cand), bool)
        out[np.argsort(ratio, kind="stable")[:limit]] = True
        out &= np.isfinite(ratio)
    return out


def readmit_supported(built, values: gtsam.Values, inlier: np.ndarray, pair_a: np.ndarray, pair_b: np.ndarray,
                      c2: np.ndarray, objective: Callable[[gtsam.Values], float], solve: Callable,
                      judge: Callable, params: GraphParams, notes: list[str]) -> tuple[gtsam.Values, np.ndarray, int]:
    """(values, inlier, LM iterations) after one joint re-solve with the rejected loops that agree with a kept loop
    over a short cycle (`pair_a`, `pair_b`: the support pairs of graph.support), judged by `judge(mask, values)`
    -> (values, kept mask over all loops, iterations): the caller's GNC-TLS over the candidates with the kept loops
    as known inliers (its map need not be solved on its labels: a set that adds loops is re-solved here), and, as
    a second start, all candidates back by LM then a TLS descent (misfits leave, re-solve, at most
    `readmit_rounds` solves); the set with the lower TLS objective whose added loops all fit
    is kept when that objective is below the one without them. Each start fails where the other works: the
    descent lost intel's loop 669 among 7 false candidates (local 30 %, seed 2; they bent the map for it), the
    GNC rejected loops 667 and 669 that fit only together (random 30 %, seed 1).

    The GNC over the supported loops may reject a loop that fits only once it is in: a loop whose residual is the
    local bend its absence leaves (intel, 30 % random, seed 1: loops 667 and 669 rejected by GNC at 2.35x and 2.65x
    their thresholds, 0.40x and 0.36x once back, TLS objective 207.52 -> 207.46). Per-loop readmission at the
    solution cannot see it (they do not fit there). Only loops supported by kept loops at least as often as by
    rejected ones are candidates: a group of mutually consistent false loops supports itself more than the kept
    map, and the group test's decision stands."""
    if not len(pair_a):
        return values, inlier, 0
    a, b = np.asarray(pair_a, int), np.asarray(pair_b, int)
    # support of each loop from kept and from rejected loops: a member of a rejected consistent group that happens to
    # agree with one kept loop is supported mostly by its own group (intel local-grouped 50 %, seed 2: such members
    # came back together and bent the map, 2.5 -> 7.0 cm); a true loop the GNC pushed out, by the map
    # counts by bincount (np.add.at is ~10x slower on w10000's 10^6 pairs; integer counts, the same numbers)
    n = len(inlier)
    ends = np.concatenate([a, b])
    other_kept = np.concatenate([inlier[b], inlier[a]])
    by_kept = np.bincount(ends, weights=other_kept.astype(float), minlength=n)
    by_rejected = np.bincount(ends, weights=(~other_kept).astype(float), minlength=n)
    cand = ~inlier & (by_kept > 0) & (by_kept >= by_rejected)
    if not cand.any():
        return values, inlier, 0
    near = nearest_candidates(built.r2(values), c2, cand, params.robust.readmit_factor,
                              params.robust.readmit_max_loops)
    if not near.any():
        notes.append(f"{int(cand.sum())} rejected loops supported by a kept loop stay out: none within "
                     "readmit_factor of its threshold")
        return values, inlier, 0
    cand = near
    # every solve below holds the kept loops and candidates only: one fill-in estimate for all (graph.linear)
    with narrow(lambda: built.pairs(inlier | cand)):
        best, iters = _readmit_starts(built, values, inlier, cand, c2, objective, solve, judge, params)
    if best is not None and best[0] < objective(values):
        _, v, trial = best
        notes.append(f"re-admitted {int((trial & ~inlier).sum())} of {int(cand.sum())} rejected loops supported by "
                     "a kept loop")
        return v, trial, iters
    notes.append(f"{int(cand.sum())} rejected loops supported by a kept loop stay out")
    return values, inlier, iters


def _readmit_starts(built, values: gtsam.Values, inlier: np.ndarray, cand: np.ndarray, c2: np.ndarray,
                    objective: Callable[[gtsam.Values], float], solve: Callable, judge: Callable,
                    params: GraphParams) -> tuple[tuple | None, int]:
    """The two starts of `readmit_supported`: ((TLS objective, values, inlier) of the better one whose added loops
    all fit, or None; LM iterations)."""
    best = None
    iters = 0
    for name in ("descent", "gnc"):
        solved = False     # `v` already solved on exactly `trial`'s loops
        if name == "descent":
            # all candidates back at once, then the misfits leave (at most `readmit_rounds` solves)
            trial, v = inlier | cand, values
            for _ in range(max(params.robust.readmit_rounds, 1)):
                v, it = solve(built.graph(trial), v, params.solver.lm_max_iterations)
                iters += it
                new = inlier | (cand & (built.r2(v) <= c2))
                if np.array_equal(new, trial):
                    solved = True
                    break
                trial = new
        else:
            v, kept, it = judge(cand, values)
            iters += it
            trial = inlier | kept
        added = trial & ~inlier
        if not added.any():
            continue
        if not solved:
            # (the descent's last solve was on these loops already: a second one from its solution is LM's
            # tolerance again, ~one whole-graph iteration on w10000)
            v, it = solve(built.graph(trial), v, params.solver.lm_max_iterations)
            iters += it
        f = objective(v)
        if bool(np.all(built.r2(v)[added] <= c2[added])) and (best is None or f < best[0]):
            best = (f, v, trial)
    return best, iters
