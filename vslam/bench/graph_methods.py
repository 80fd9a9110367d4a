"""The methods `vslam bench graph` runs side by side on the same graph: ours, GTSAM's GNC, g2o with DCS, plain LM.

Each takes a `PoseGraphData` and returns a `MethodRun`: optimised poses (rows in node order), a kept flag per loop
(loop order), seconds (graph construction included; file reading and outlier injection excluded).
Peers are configured as their papers / libraries recommend for this use:
- GTSAM GNC: `gtsam.GncLMOptimizer`, truncated least squares, anchor and odometry as known inliers, gtsam's default
  inlier threshold (chi-square 0.99 of the factor dimension), started from the odometry chain; kept = weight > 0.5;
- DCS: Levenberg-Marquardt with the dynamic covariance scaling kernel (Agarwal et al. 2013, phi = 1, the paper's
  value; gtsam.noiseModel.mEstimator.DCS) on every loop, odometry plain, first pose anchored, started from the
  odometry chain; kept = DCS scale s = min(1, 2 phi / (phi + chi^2)) >= 0.5 (method "dcs");
- g2o DCS: the same problem solved by g2o itself (LM + `RobustKernelDCS`, phi = 1, same start, same kept rule) in a
  child process (vslam.bench.graph_g2o), so a native crash loses one row ("crashed"), not the run (method "g2o-dcs");
- plain LM: least squares (LAGO in 2D / chordal in 3D, then LM) on every loop; it keeps every loop.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np

from graph import GraphParams, optimize
from graph.batch import build, initial_guess, lm_params
from graph.factors import array_from_values, graph_of, squared_residuals, values_from_array
from graph.model import PoseGraphData
from graph.params import InitMethod
from graph.robust import robust_solve
from vslam.bench.graph_g2o import solve_in_child

DCS_PHI = 1.0


@dataclass
class MethodRun:
    poses: np.ndarray
    kept: np.ndarray
    seconds: float
    note: str = ""


def ours(data: PoseGraphData, params: GraphParams | None = None) -> MethodRun:
    t0 = time.perf_counter()
    res = robust_solve(data, params or GraphParams())
    return MethodRun(res.poses, np.asarray(res.loop_inlier, bool), time.perf_counter() - t0)


def ours_isam2(data: PoseGraphData, params: GraphParams | None = None) -> MethodRun:
    """Ours with the incremental strategy on the whole graph (`vslam graph optimize --solver isam2`)."""
    t0 = time.perf_counter()
    res = optimize(data, params or GraphParams(), solver="isam2")
    return MethodRun(res.poses, np.asarray(res.loop_inlier, bool), time.perf_counter() - t0)


def ours_setting(**robust):
    """Ours with the given `robust` settings (a setting's other side, side by side with `ours` in one run)."""
    def run(data: PoseGraphData) -> MethodRun:
        return ours(data, GraphParams().replace(robust=robust))
    return run


def plain_lm(data: PoseGraphData) -> MethodRun:
    t0 = time.perf_counter()
    res = optimize(data, GraphParams.preset("least_squares"))
    return MethodRun(res.poses, np.ones(data.num_loops, bool), time.perf_counter() - t0)


def gtsam_gnc(data: PoseGraphData) -> MethodRun:
    t0 = time.perf_counter()
    params = GraphParams.preset("least_squares")
    built = build(data, params)
    init = values_from_array(data.dim, initial_guess(data, built, InitMethod.ODOMETRY))
    g = built.graph()
    gp = gtsam.GncLMParams(lm_params(params))
    gp.setLossType(gtsam.GncLossType.TLS)
    gp.setKnownInliers(list(range(len(built.priors) + len(built.odometry))))
    opt = gtsam.GncLMOptimizer(g, init, gp)
    values = opt.optimize()
    w = np.asarray(opt.getWeights(), float)[len(built.priors) + len(built.odometry):]
    return MethodRun(array_from_values(data.dim, values, data.num_nodes), w > 0.5, time.perf_counter() - t0)


def dcs(data: PoseGraphData, phi: float = DCS_PHI) -> MethodRun:
    t0 = time.perf_counter()
    params = GraphParams.preset("least_squares")
    built = build(data, params)
    init = values_from_array(data.dim, initial_guess(data, built, InitMethod.ODOMETRY))
    kernel = gtsam.noiseModel.mEstimator.DCS.Create(phi)
    loops = [f.cloneWithNewNoiseModel(gtsam.noiseModel.Robust.Create(kernel, f.noiseModel())) for f in built.loops]
    g = graph_of(built.priors + built.odometry + loops)
    values = gtsam.LevenbergMarquardtOptimizer(g, init, lm_params(params)).optimize()
    chi2 = squared_residuals(built.loops, values)
    kept = np.minimum(1.0, 2.0 * phi / (phi + chi2)) >= 0.5
    return MethodRun(array_from_values(data.dim, values, data.num_nodes), kept, time.perf_counter() - t0)


def g2o_dcs(data: PoseGraphData, phi: float = DCS_PHI) -> MethodRun:
    """g2o's LM with its DCS kernel, in a child process (raises graph_g2o.PeerCrashed when the child dies).
    Seconds: the child's solve (graph construction in g2o included; process start and file exchange excluded)."""
    params = GraphParams.preset("least_squares")
    built = build(data, params)
    init = initial_guess(data, built, InitMethod.ODOMETRY)
    poses, chi2, seconds = solve_in_child(data.dim, init, built.a, built.b, data.measurements, data.information,
                                          data.is_loop, built.anchors, phi)
    kept = np.minimum(1.0, 2.0 * phi / (phi + chi2)) >= 0.5
    return MethodRun(poses, kept, seconds)


METHODS = {"ours": ours, "ours-isam2": ours_isam2,
           "ours-own-off": ours_setting(own_cycle_test=False),
           "ours-screen-on": ours_setting(short_tail_screen=True), "ours-screen-off": ours_setting(short_tail_screen=False),
           "ours-h16-off": ours_setting(screen_local=False, screen_family_bound=False, retry_clusters=0),
           "ours-refine-on": ours_setting(calibration_refine=5), "ours-refine-off": ours_setting(calibration_refine=0),
           "ours-cycles-5000": ours_setting(calibration_propagate=5000),
           "ours-joint-off": ours_setting(disputed_clusters=0),
           "gtsam-gnc": gtsam_gnc, "dcs": dcs, "g2o-dcs": g2o_dcs, "plain-lm": plain_lm}
# peers run on contaminated graphs only up to --peer-max-nodes (minutes per row beyond)
PEERS_LIMITED = ("gtsam-gnc", "plain-lm", "g2o-dcs")
