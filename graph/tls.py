"""Truncated least squares over loop closures: the objective, its GNC (one weight per cluster of loops) and the
admission of loops that fit at a solution. The pieces every step of the consensus solve (graph.robust) shares.

TLS charges a loop min(r^2, c^2) / 2: a loop beyond its threshold c^2 costs a constant and pulls nothing, so the
objective compares loop sets directly. GNC (Yang et al. 2020) reaches it from a convex surrogate by a rising mu.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.batch import BuiltGraph, solve_lm
from graph.factors import graph_of
from graph.gnc import tls_weights
from graph.linear import costly, graph_pairs
from graph.params import GraphParams


def weighted_graph(base_factors: list, loops: list, weights: np.ndarray, floor: float = 1e-9
                   ) -> gtsam.NonlinearFactorGraph:
    """`base_factors` + each loop at its weight; a weight at or below `floor` leaves the loop out."""
    g = graph_of(base_factors)
    for f, w in zip(loops, weights.tolist()):
        if w >= 1.0 - 1e-9:
            g.add(f)
        elif w > floor:
            r = np.asarray(f.noiseModel().R(), float)
            g.add(f.cloneWithNewNoiseModel(gtsam.noiseModel.Gaussian.SqrtInformation(np.sqrt(w) * r)))
    return g


def _loop_factor(f, w: float, floor: float = 1e-9):
    """The loop factor at weight w (None: out), as `weighted_graph` builds it."""
    if w >= 1.0 - 1e-9:
        return f
    if w > floor:
        r = np.asarray(f.noiseModel().R(), float)
        return f.cloneWithNewNoiseModel(gtsam.noiseModel.Gaussian.SqrtInformation(np.sqrt(w) * r))
    return None


def _is_pose2(values: gtsam.Values) -> bool:
    try:
        values.atPose2(values.keys()[0])
        return True
    except RuntimeError:
        return False


class _IsamSteps:
    """Warm GNC steps by iSAM2 (the re-admission's GNC, `readmit_isam2_steps`): the graph is held once; a step
    removes and re-adds only the loops whose weight changed and re-factors the cliques they and the moved poses
    touch."""

    def __init__(self, base: list, loops: list, values: gtsam.Values, relinearize: float,
                 gauss_newton: bool = False, floor: float = 1e-9):
        p = gtsam.ISAM2Params()
        if gauss_newton:
            # undamped, with the whole back-substitution (wildfire 0: no stale part of the step): where only a few
            # candidates are re-weighted against a fixed map (`readmit_isam2_gauss_newton`); dogleg's step
            # evaluates the whole graph's error, ~0.2 s of a ~0.3 s step on w10000
            p.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(0.0))
        else:
            # Powell's dogleg, not Gauss-Newton: the LM steps it stands for are damped, and undamped steps took ring
            # at 50 % random-grouped to other labels (60 % of the false loops rejected, 43.9 m)
            p.setOptimizationParams(gtsam.ISAM2DoglegParams())
        # a between factor's error is linear in the poses' translations once their rotations are fixed (2D and 3D,
        # gtsam's exponential charts), so only a rotation update calls for a new linearisation: a GNC step shifts
        # the whole map by centimetres, and a translation threshold re-factored every pose every step
        planar = _is_pose2(values)
        thr = np.array([np.inf, np.inf, relinearize]) if planar else np.array([relinearize] * 3 + [np.inf] * 3)
        m = gtsam.ISAM2ThresholdMap()
        m.insert(("\x00", np.minimum(thr, 1e300)))
        p.setRelinearizeThreshold(m)
        p.relinearizeSkip = 1
        self.isam = gtsam.ISAM2(p)
        self.loops = loops
        self.base = base
        self.values = values
        self.floor = floor
        self.weight = np.full(len(loops), np.nan)     # weight each loop is held at (nan: not yet added)
        self.index = np.full(len(loops), -1, np.int64)  # its factor index in iSAM2 (-1: out)

    def step(self, w: np.ndarray) -> gtsam.Values:
        """One iSAM2 update at weights `w` (a second update per step re-linearised nearly every pose, since a step
        moves the whole map beyond the threshold, and cost about one LM iteration)."""
        new = gtsam.NonlinearFactorGraph()
        first = np.all(np.isnan(self.weight))
        if first:
            new.push_back(graph_of(self.base))
        changed = np.flatnonzero(~(w == self.weight))
        remove = [int(i) for i in self.index[changed] if i >= 0]
        added = []
        for k in changed.tolist():
            f = _loop_factor(self.loops[k], float(w[k]), self.floor)
            self.index[k] = -1
            if f is not None:
                new.add(f)
                added.append(k)
        self.weight = w.copy()
        r = self.isam.update(new, self.values if first else gtsam.Values(), remove)
        idx = np.asarray(r.getNewFactorsIndices(), np.int64)
        self.index[np.asarray(added, np.int64)] = idx[len(idx) - len(added):]
        return self.isam.calculateEstimate()


def gnc_tls(base: list, sub: BuiltGraph, values: gtsam.Values, c2: np.ndarray, label: np.ndarray,
            params: GraphParams, isam2_gauss_newton: bool = False, final_solve: bool = True,
            zero_below_tol: bool = False, isam2_steps: bool = False) -> tuple[gtsam.Values, np.ndarray, int, int]:
    """GNC-TLS over the loops of `sub` from `values` with one weight per label (cluster); returns (values,
    inlier per loop, outer steps, LM iterations). Odometry + anchor (`base`) are known inliers.
    `isam2_steps`: take the warm steps by iSAM2 updates that re-weight only the changed loops (`_IsamSteps`; the
    re-admission's GNC, `readmit_isam2_steps`), where at most `readmit_isam2_max_changed` loops change weight;
    `isam2_gauss_newton`: those steps by Gauss-Newton instead of dogleg.
    `final_solve` False: the caller solves the returned labels to convergence itself (or discards the map), so the
    GNC ends at the step whose weights no longer change without solving it, and without the warm LM step after
    iSAM2 steps; the labels are the same, the map is the last step's.
    `zero_below_tol`: a loop whose weight is below `gnc_weights_tol` (the tolerance at which the stopping test
    already counts a weight as 0) leaves the step's graph instead of staying in it at that weight (the reduced graph
    of graph.cluster_start, `cluster_zero_weights`)."""
    loops = sub.loops
    L = len(loops)
    n_cl = int(label.max()) + 1 if L else 0
    c2_cl = np.bincount(label, weights=c2, minlength=n_cl) if L else np.zeros(0)
    weights = np.ones(n_cl)
    outer = iters = 0
    if not L:
        return values, np.zeros(0, bool), 0, 0
    r2_cl = np.bincount(label, weights=sub.r2(values), minlength=n_cl)
    excess = 2.0 * r2_cl - c2_cl
    if np.any(r2_cl > c2_cl):
        pos = excess > 0
        mu = max(float(np.min(c2_cl[pos] / excess[pos])), 1e-6)
        tol = params.robust.gnc_weights_tol
        floor = tol if zero_below_tol else 1e-9
        # iSAM2 only where the scope would factor the step's graph directly (its fill-in is the same)
        use_isam = isam2_steps and not costly(
            lambda: graph_pairs(weighted_graph(base, loops, np.ones(L))))
        isam, polish = None, False
        for outer in range(1, params.robust.gnc_max_iterations + 1):
            new_w = tls_weights(r2_cl, c2_cl, mu)
            inner = params.robust.consensus_inner_iterations
            if (params.robust.consensus_binary_converge and outer > 1
                    and bool(np.all((new_w < tol) | (new_w > 1 - tol)))
                    and float(np.max(np.abs(new_w - weights))) >= tol):
                # binary weights that still change: the surrogate is TLS itself from here on, and a few warm
                # iterations per step only creep towards the next labels (a label-flip tail of 40+ steps)
                inner = params.solver.lm_max_iterations
            if (not final_solve and outer > 1 and bool(np.all((new_w < tol) | (new_w > 1 - tol)))
                    and float(np.max(np.abs(new_w - weights))) < tol):
                # the last step (binary weights, no change): its solve would only move the map the caller re-solves
                weights = new_w
                polish = False
                break
            changed = int(np.count_nonzero(new_w[label] != weights[label]))
            # a fresh iSAM2 costs one batch factorisation and, at the end, one LM polish: not for a step that
            # changes no weight (the last step of a run after a step solved to convergence)
            few = (use_isam and inner == params.robust.consensus_inner_iterations
                   and changed <= params.robust.readmit_isam2_max_changed and (isam is not None or changed > 0))
            if few:
                if isam is None:
                    isam = _IsamSteps(base, loops, values, params.robust.readmit_isam2_relinearize,
                                       isam2_gauss_newton, floor)
                values = isam.step(new_w[label])
                iters += 1
                polish = True
            else:
                # a step to convergence, or many loops re-weighted (a near-batch re-factorisation by iSAM2, with
                # its own ordering of the changed part: one such step took 4.6 s on w10000): LM on the whole graph.
                # iSAM2's linearisation is then stale: it starts again from this solution when needed
                isam = None
                values, it = solve_lm(weighted_graph(base, loops, new_w[label], floor), values, params, inner)
                iters += it
                polish = False
            r2_cl = np.bincount(label, weights=sub.r2(values), minlength=n_cl)
            change = float(np.max(np.abs(new_w - weights)))
            weights = new_w
            if bool(np.all((weights < tol) | (weights > 1 - tol))) and change < tol:
                break
            mu *= params.robust.consensus_mu_step
        if polish and final_solve:
            # iSAM2's estimate is a few partial Gauss-Newton steps: the warm LM step the LM path ends on, from it
            values, it = solve_lm(weighted_graph(base, loops, weights[label], floor), values, params,
                                  params.robust.consensus_inner_iterations)
            iters += it
    return values, (weights > 0.5)[label], outer, iters


def tls_objective(base_graph: gtsam.NonlinearFactorGraph, loops: BuiltGraph, values: gtsam.Values,
                  c2: np.ndarray) -> float:
    """The truncated-least-squares objective: cost(anchor + odometry) + sum over the loops of `loops` of
    min(r^2, c^2) / 2."""
    return float(base_graph.error(values)) + 0.5 * float(np.minimum(loops.r2(values), c2).sum())


def admit_fitting(built, values: gtsam.Values, inlier: np.ndarray, c2: np.ndarray, params: GraphParams,
             notes: list[str]) -> tuple[gtsam.Values, np.ndarray, int]:
    """Admit every loop that fits its threshold at the solution and re-solve, until none is added (at most
    `readmit_rounds` solves)."""
    iters = 0
    for _ in range(params.robust.readmit_rounds):
        readmit = ~inlier & (built.r2(values) <= c2)
        if not readmit.any():
            break
        inlier = inlier | readmit
        values, it = solve_lm(built.graph(inlier), values, params, params.solver.lm_max_iterations)
        iters += it
        notes.append(f"admitted {int(readmit.sum())} loops that fit at the solution")
    return values, inlier, iters
