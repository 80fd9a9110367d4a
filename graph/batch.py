"""Batch optimisation of a `PoseGraphData`: initial guess, robust loop handling, Levenberg-Marquardt.

`solve` is the LM solve behind the `Direct`, `ArrivalGate` and `SplitChain` robust methods (graph.rejection); the
consensus method (graph.robust) uses its building blocks. docs/graph.md has the measurements behind each step:
1. robust solve of odometry + the candidate loops (all, or those the arrival gate admitted): GNC, Huber or Cauchy;
2. re-initialise from odometry + kept loops (LAGO / chordal), re-solve, and re-test every loop, deferred ones
   included, against thresholds scaled to the residual level of the kept loops; repeat until labels settle.
Factor layout handed to gtsam: anchor priors, odometry edges, loop edges (each in data order), so the known
inliers of GNC are the leading factor indices.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np

from graph.consistency import isolated, standardized_residuals
from graph.errors import GraphError
from graph.factors import (
    NoiseCache,
    anchor_nodes,
    array_from_values,
    between_factors,
    graph_of,
    prior_factors,
    squared_residuals,
    to_pose,
    values_from_array,
)
from graph.gnc import gnc_optimize
from graph.initial import InitialGuessError, chordal_guess, lago_guess, spanning_tree_guess
from graph.linear import configure, run_lm
from graph.model import TANGENT_DIM, PoseGraphData
from graph.params import GncImpl, GncLoss, GraphParams, InitMethod, RobustMode
from graph.residuals import LoopResiduals
from graph.result import GraphResult
from graph.thresholds import fence_scale, information_scale, loop_thresholds


def resolve_init(data: PoseGraphData, params: GraphParams) -> InitMethod:
    """AUTO: LAGO (2D) / chordal (3D) for least squares; the odometry tree when loops may be false (see docs/graph.md)."""
    m = params.solver.init
    if m == InitMethod.AUTO:
        if params.robust.method == RobustMode.NONE:
            return InitMethod.LAGO if data.dim == 2 else InitMethod.CHORDAL
        return InitMethod.ODOMETRY
    if m == InitMethod.LAGO and data.dim != 2:
        raise GraphError("LAGO initialisation is for planar (2D) graphs; use chordal or odometry for 3D")
    if m == InitMethod.CHORDAL and data.dim != 3:
        raise GraphError("chordal initialisation is for 3D graphs; use lago or odometry for 2D")
    return m


@dataclass
class BuiltGraph:
    """gtsam factors for a graph, in the batch layout (loops: Gaussian, in data order)."""

    priors: list
    odometry: list
    loops: list
    odo_idx: np.ndarray
    loop_idx: np.ndarray
    anchors: np.ndarray
    a: np.ndarray
    b: np.ndarray
    residuals: LoopResiduals | None = None      # vectorised r^2 of `loops` (graph.residuals)

    def subset(self, keep: np.ndarray) -> "BuiltGraph":
        """The same graph with only the loops selected by a boolean mask over `loops`."""
        keep = np.asarray(keep, bool)
        return BuiltGraph(self.priors, self.odometry, [f for f, k in zip(self.loops, keep.tolist()) if k],
                          self.odo_idx, self.loop_idx[keep], self.anchors, self.a, self.b,
                          None if self.residuals is None else self.residuals.subset(keep))

    def r2(self, values: gtsam.Values) -> np.ndarray:
        """Squared Mahalanobis residual of every loop at `values` (= squared_residuals(loops, values))."""
        if self.residuals is None:
            return squared_residuals(self.loops, values)
        return self.residuals(values)

    def pairs(self, keep: np.ndarray | None = None) -> np.ndarray:
        """(E, 2) node pairs of the graph's factors (anchor priors as (k, k)), for graph.linear's fill-in estimate."""
        loops = self.loop_idx if keep is None else self.loop_idx[np.asarray(keep, bool)]
        idx = np.concatenate([self.odo_idx, loops])
        anchors = np.asarray(self.anchors, np.int64)
        return np.vstack([np.column_stack([anchors, anchors]), np.column_stack([self.a[idx], self.b[idx]])])

    def graph(self, keep: np.ndarray | None = None) -> gtsam.NonlinearFactorGraph:
        loops = self.loops if keep is None else [f for f, k in zip(self.loops, keep.tolist()) if k]
        return graph_of(self.priors + self.odometry + loops)


def build(data: PoseGraphData, params: GraphParams) -> BuiltGraph:
    a, b = data.edge_index_pairs()
    anchors = anchor_nodes(data)
    cache = NoiseCache(data.dim)
    odo_idx = np.flatnonzero(~data.is_loop)
    loop_idx = np.flatnonzero(data.is_loop)
    priors = prior_factors(data, anchors, data.poses, params.solver.anchor_sigma)
    odometry = between_factors(data, odo_idx, a, b, cache=cache)
    scale = information_scale(data.probability[loop_idx], params)
    loops = between_factors(data, loop_idx, a, b, scale, cache)
    return BuiltGraph(priors, odometry, loops, odo_idx, loop_idx, anchors, a, b,
                      LoopResiduals.of_edges(data, loop_idx, a, b, loops, scale))


def initial_guess(data: PoseGraphData, built: BuiltGraph, method: InitMethod) -> np.ndarray:
    if method == InitMethod.ODOMETRY:
        return spanning_tree_guess(data, built.anchors, data.poses[built.anchors], built.a, built.b)
    if method == InitMethod.GIVEN:
        guess = data.poses.copy()
        missing = np.isnan(guess).any(axis=1)
        if missing.any():
            tree = spanning_tree_guess(data, built.anchors, data.poses[built.anchors], built.a, built.b)
            guess[missing] = tree[missing]
        return guess
    if method == InitMethod.LAGO:
        # gtsam's LAGO accepts diagonal noise models only: use the marginal standard deviations of each edge
        return lago_guess(graph_of(built.priors + _diagonal_factors(data, built)), data.num_nodes)
    return chordal_guess(built.graph(), data.num_nodes)


def _diagonal_factors(data: PoseGraphData, built: BuiltGraph) -> list:
    idx = np.concatenate([built.odo_idx, built.loop_idx])
    info = data.information[idx]
    if np.all(info == info * np.eye(3)):
        return built.odometry + built.loops       # already diagonal (gtsam made them Diagonal models)
    sig = np.sqrt(np.diagonal(np.linalg.inv(info), axis1=1, axis2=2))
    cache: dict[bytes, object] = {}
    out = []
    for e, s in zip(idx.tolist(), sig):
        nm = cache.get(s.tobytes())
        if nm is None:
            nm = cache[s.tobytes()] = gtsam.noiseModel.Diagonal.Sigmas(s)
        out.append(gtsam.BetweenFactorPose2(int(built.a[e]), int(built.b[e]), to_pose(2, data.measurements[e]), nm))
    return out


def lm_params(params: GraphParams, max_iter: int | None = None,
              graph: gtsam.NonlinearFactorGraph | None = None) -> gtsam.LevenbergMarquardtParams:
    """LM parameters of a batch solve; with `graph`, the linear solver is chosen for it (graph.linear)."""
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(params.solver.lm_max_iterations if max_iter is None else max_iter)
    p.setRelativeErrorTol(params.solver.lm_relative_tol)
    p.setAbsoluteErrorTol(params.solver.lm_absolute_tol)
    return configure(p, graph)


def solve_lm(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, params: GraphParams,
             max_iter: int | None = None) -> tuple[gtsam.Values, int]:
    """LM from `values` at the solver tolerances of `params` (`max_iter`: its iteration cap instead of
    `solver.lm_max_iterations`); returns (values, iterations)."""
    s = params.solver
    return run_lm(graph, values, s.lm_max_iterations if max_iter is None else max_iter, s.lm_relative_tol,
                  s.lm_absolute_tol)


def mestimator(mode: RobustMode, params: GraphParams):
    if mode == RobustMode.HUBER:
        return gtsam.noiseModel.mEstimator.Huber.Create(params.robust.huber_k)
    if mode == RobustMode.CAUCHY:
        return gtsam.noiseModel.mEstimator.Cauchy.Create(params.robust.cauchy_k)
    return None


def robust_loop_factors(loops: list, mode: RobustMode, params: GraphParams) -> list:
    """Loop factors wrapped in an M-estimator (one robust model per distinct Gaussian model)."""
    est = mestimator(mode, params)
    if est is None:
        return list(loops)
    cache: dict[bytes, object] = {}
    out = []
    for f in loops:
        nm = f.noiseModel()
        key = np.asarray(nm.R(), float).tobytes()     # wrappers are new objects per call: key on the matrix
        r = cache.get(key)
        if r is None:
            r = cache[key] = gtsam.noiseModel.Robust.Create(est, nm)
        out.append(f.cloneWithNewNoiseModel(r))
    return out


def mestimator_weights(r2: np.ndarray, mode: RobustMode, params: GraphParams) -> np.ndarray:
    """IRLS weight of each loop at its residual (Huber / Cauchy); 1 for least squares."""
    r = np.sqrt(np.maximum(np.asarray(r2, float), 0.0))
    if mode == RobustMode.HUBER:
        return np.where(r <= params.robust.huber_k, 1.0, params.robust.huber_k / np.maximum(r, 1e-300))
    if mode == RobustMode.CAUCHY:
        return 1.0 / (1.0 + (r / params.robust.cauchy_k) ** 2)
    return np.ones_like(r)


def solve(data: PoseGraphData, params: GraphParams, candidates: np.ndarray | None = None) -> GraphResult:
    """Levenberg-Marquardt with the robust mode of `params`; `candidates` (bool per loop) limits the robust
    stage to those loops, the others start as outliers and are re-tested in the re-initialisation rounds."""
    t_start = time.perf_counter()
    built = build(data, params)
    L = len(built.loops)
    cand = np.ones(L, bool) if candidates is None else np.asarray(candidates, bool)
    if len(cand) != L:
        raise ValueError(f"{len(cand)} candidate flags for {L} loops")
    method = resolve_init(data, params)
    t0 = time.perf_counter()
    notes: list[str] = []
    try:
        guess = initial_guess(data, built, method)
    except InitialGuessError as exc:      # LAGO / chordal cannot run on this graph: the odometry tree always can
        guess = initial_guess(data, built, InitMethod.ODOMETRY)
        notes.append(f"{exc}; started from the odometry tree instead")
    init_seconds = time.perf_counter() - t0
    init_values = values_from_array(data.dim, guess)
    c2 = loop_thresholds(data.probability[built.loop_idx], TANGENT_DIM[data.dim], params)
    gnc_iters = 0
    sub = built.subset(cand)
    inlier = np.zeros(L, bool)
    if params.robust.method == RobustMode.GNC and params.robust.gnc_impl == GncImpl.WARM:
        out = gnc_optimize(graph_of(built.priors + built.odometry), sub.loops, init_values, c2[cand],
                           loss=params.robust.gnc_loss, mu_step=params.robust.gnc_mu_step,
                           max_iterations=params.robust.gnc_max_iterations,
                           inner_iterations=params.robust.gnc_inner_iterations,
                           final_iterations=params.solver.lm_max_iterations,
                           weights_tol=params.robust.gnc_weights_tol, cost_tol=params.robust.gnc_cost_tol,
                           rel_tol=params.solver.lm_relative_tol, abs_tol=params.solver.lm_absolute_tol,
                           mu_floor=params.robust.gnc_mu_floor if candidates is not None else 0.0)
        values, iters, gnc_iters = out.values, out.lm_iterations, out.outer_iterations
        initial_cost, final_cost = out.initial_cost, out.final_cost
        inlier[cand] = out.weights > 0.5
    elif params.robust.method == RobustMode.GNC:
        g = sub.graph()
        gp = gtsam.GncLMParams(lm_params(params))
        gp.setLossType(gtsam.GncLossType.TLS if params.robust.gnc_loss == GncLoss.TLS else gtsam.GncLossType.GM)
        gp.setKnownInliers(list(range(len(built.priors) + len(built.odometry))))
        opt = gtsam.GncLMOptimizer(g, init_values, gp)
        # gtsam takes one threshold for all factors (on the error 0.5 r^2): the median loop threshold
        opt.setInlierCostThresholds(0.5 * float(np.median(c2[cand])) if cand.any() else 0.5 * float(np.max(c2, initial=11.34)))
        values = opt.optimize()
        w = np.asarray(opt.getWeights(), float)[len(built.priors) + len(built.odometry):]
        iters = 0
        initial_cost = float(g.error(init_values))
        inlier[cand] = w > 0.5
        final_cost = float(built.graph(inlier).error(values))
        notes.append("gtsam.GncLMOptimizer: iteration count not exposed")
    else:
        g = graph_of(built.priors + built.odometry + robust_loop_factors(sub.loops, params.robust.method, params))
        opt = gtsam.LevenbergMarquardtOptimizer(g, init_values, lm_params(params, graph=g))
        values = opt.optimize()
        iters = int(opt.iterations())
        initial_cost, final_cost = float(g.error(init_values)), float(g.error(values))
        r2 = squared_residuals(built.loops, values)
        inlier = cand & (r2 <= c2)
    if params.robust.method != RobustMode.NONE and params.robust.reinit_rounds > 0 and L:
        values, inlier, final_cost, rounds, it2, scale = _reinit_rounds(data, built, params, values, inlier, c2)
        iters += it2
        notes.append(f"re-initialised from the kept loops: {rounds} round(s); residual scale {scale:.3g}")
    r2 = squared_residuals(built.loops, values)
    if params.robust.method in (RobustMode.GNC, RobustMode.NONE):
        weights = inlier.astype(float) if params.robust.method == RobustMode.GNC else np.ones(L)
    else:
        weights = mestimator_weights(r2, params.robust.method, params)
    if params.robust.method == RobustMode.NONE:
        inlier = r2 <= c2            # least squares keeps every loop; the label says whether it fits
    poses = array_from_values(data.dim, values, data.num_nodes)
    seconds = time.perf_counter() - t0
    notes.append(f"factor construction {t0 - t_start:.3f} s (not in seconds)")
    return GraphResult(data.dim, data.node_ids.copy(), poses, built.loop_idx, inlier, weights, r2, initial_cost,
                       final_cost, iters, seconds, init_seconds, params.solver.method.value, params.robust.method.value,
                       method.value, gnc_iters, notes)


def _reinit_rounds(data: PoseGraphData, built: BuiltGraph, params: GraphParams, values: gtsam.Values,
                   inlier: np.ndarray, c2: np.ndarray):
    """Settle the labels by descending the truncated-least-squares objective
        f(x) = cost(prior + odometry) + sum over loops of min(r_k^2(x), s c_k^2) / 2,
    s = `fence_scale` of the kept loops' residuals (1 without `calibrate_noise`). Each round proposes
    - the current labels, polished by LM;
    - the current labels, re-initialised from odometry + kept loops (LAGO in 2D, chordal in 3D): a robust solve
      started from a poor guess can label almost every loop right and still sit in a bent local minimum;
    - the kept loops minus the suspects (kept with r^2 > s c^2), re-initialised likewise;
    - also minus the isolated kept loops whose standardized residual exceeds s c^2 (graph.consistency): a false loop
      that fits its threshold inside a map bent around it;
    - plus the rejected loops within `readmit_factor` of their threshold: true loops deferred by the gate can miss
      the threshold in a map that lacks them, and only fit once they are in;
    takes the proposal with the lowest f, and re-labels every loop (r^2 <= s c^2), deferred ones included. Stops when
    nothing improves and the labels hold. At most `reinit_max_solves` re-initialisations in all (each is one LAGO /
    chordal solve and a full LM: ~1 s on w10000); past that, proposals are only polished from the current values.
    Returns (values, labels, final cost of the kept graph, rounds,
    LM iterations, scale s).
    """
    iters = 0
    rounds = 0
    method = InitMethod.LAGO if data.dim == 2 else InitMethod.CHORDAL
    dof = TANGENT_DIM[data.dim]
    base = graph_of(built.priors + built.odometry)

    def tls(v, thr):
        r2 = squared_residuals(built.loops, v)
        return float(base.error(v)) + 0.5 * float(np.minimum(r2, thr).sum()), r2

    budget = [params.robust.reinit_max_solves]

    def from_scratch(labels):
        if budget[0] <= 0:
            return solve_lm(built.graph(labels), values, params)       # budget spent: warm start only
        budget[0] -= 1
        try:
            guess = values_from_array(data.dim, initial_guess(data, built.subset(labels), method))
        except RuntimeError:
            # the chordal relaxation can be indeterminate for some loop subsets (sphere2500): warm start instead
            return solve_lm(built.graph(labels), values, params)
        return solve_lm(built.graph(labels), guess, params)

    r2 = squared_residuals(built.loops, values)
    pos_a, pos_b = built.a[built.loop_idx], built.b[built.loop_idx]
    scale = 1.0
    for rounds in range(1, params.robust.reinit_rounds + 1):
        if params.robust.calibrate_noise:
            scale = fence_scale(r2[inlier], dof, params.robust.fence_factor, params.robust.fence_quantile)
        thr = c2 * scale
        best_f, r2 = tls(values, thr)
        proposals = []
        candidates = [inlier, inlier & (r2 <= thr)]
        if params.robust.readmit_factor > 1.0:
            near = ~inlier & (r2 <= params.robust.readmit_factor * thr)
            if near.any():
                candidates.append((inlier & (r2 <= thr)) | near)
        if params.robust.isolation_window > 0:
            iso = isolated(pos_a, pos_b, inlier, params.robust.isolation_window)
            if iso.sum() > params.robust.isolation_max_tests:
                # joint marginals cost ~1-25 ms each: test the isolated loops closest to their threshold
                ratio = np.where(iso, r2 / thr, -np.inf)
                iso = np.zeros_like(iso)
                iso[np.argsort(-ratio)[:params.robust.isolation_max_tests]] = True
            w = standardized_residuals(built.graph(inlier), values, built.loops, iso)
            candidates.append(candidates[1] & ~(iso & (w > thr)))
        for n, labels in enumerate(candidates):
            if n > 0 and any(np.array_equal(labels, c) for c in candidates[:n]):
                continue
            if labels is inlier:
                v, it = solve_lm(built.graph(labels), values, params)       # polish
                iters += it
                proposals.append(v)
            v, it = from_scratch(labels)
            iters += it
            proposals.append(v)
        improved = False
        for v in proposals:
            f, r2v = tls(v, thr)
            if f < best_f - 1e-9 * max(1.0, abs(best_f)):
                best_f, values, r2, improved = f, v, r2v, True
        new = r2 <= thr
        if not improved and np.array_equal(new, inlier):
            break
        inlier = new
    values, it = solve_lm(built.graph(inlier), values, params)
    return values, inlier, float(built.graph(inlier).error(values)), rounds, iters + it, scale
