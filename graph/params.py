"""Options and tunables of the pose-graph back end, gathered in one dataclass with named presets.

Enums carry the values used on the command line (`--robust gnc|huber|cauchy|none`, `--solver lm|isam2`).
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, replace

from odometry.shared.errors import ConfigError


class RobustMode(str, enum.Enum):
    """How loop closures are protected against false positives (odometry is always trusted)."""

    GNC = "gnc"          # graduated non-convexity (truncated least squares), odometry as known inliers
    HUBER = "huber"      # Huber M-estimator on loop factors
    CAUCHY = "cauchy"    # Cauchy M-estimator on loop factors
    NONE = "none"        # plain least squares


class Solver(str, enum.Enum):
    LM = "lm"            # batch Levenberg-Marquardt
    ISAM2 = "isam2"      # incremental smoothing and mapping


class GncLoss(str, enum.Enum):
    TLS = "tls"          # truncated least squares: binary inlier / outlier weights
    GM = "gm"            # Geman-McClure: soft weights


class GncImpl(str, enum.Enum):
    WARM = "warm"        # graph.gnc: warm-started inner solves, per-loop thresholds (default, see README)
    GTSAM = "gtsam"      # gtsam.GncLMOptimizer (restarts every inner solve from the initial values)


class InitMethod(str, enum.Enum):
    """Initial guess for the batch solver."""

    AUTO = "auto"            # LAGO for planar graphs without robust mode, odometry chain otherwise; chordal in 3D
    LAGO = "lago"            # linear approximation for graph optimisation (planar only)
    ODOMETRY = "odometry"    # compose odometry edges along a spanning tree from the anchor
    CHORDAL = "chordal"      # chordal rotation relaxation (gtsam.InitializePose3), 3D only
    GIVEN = "given"          # the node guesses as given (file vertices / add_node)


class LoopWeighting(str, enum.Enum):
    """How a loop's probability P(loop | score) enters the optimisation."""

    NONE = "none"                # ignored
    THRESHOLD = "threshold"      # shifts the loop's inlier threshold by 2 * logit(p) (Bayesian inlier test)
    INFORMATION = "information"  # scales the loop's information matrix by p


@dataclass(frozen=True)
class GraphParams:
    """Every tunable of the back end. Use a preset and `with_(...)` to change single fields."""

    solver: Solver = Solver.LM
    robust: RobustMode = RobustMode.GNC
    init: InitMethod = InitMethod.AUTO
    # --- batch Levenberg-Marquardt
    lm_max_iterations: int = 100
    lm_relative_tol: float = 1e-5
    lm_absolute_tol: float = 1e-5
    # --- anchor: a prior on the first node (or on the file's FIX vertices), standard deviation per axis
    anchor_sigma: float = 1e-6
    # --- robust loops
    inlier_probability: float = 0.99     # chi-square quantile of a loop's Mahalanobis residual for an inlier
    gnc_loss: GncLoss = GncLoss.TLS
    gnc_impl: GncImpl = GncImpl.WARM
    gnc_mu_step: float = 1.4             # factor on the GNC control parameter per outer iteration
    gnc_max_iterations: int = 100        # outer iterations
    gnc_inner_iterations: int = 5        # LM iterations per outer iteration (warm-started)
    gnc_mu_floor: float = 1.0            # initial control parameter at least this after the gate's warm start
    gnc_weights_tol: float = 1e-4        # stop when weights are binary to this tolerance (TLS)
    gnc_cost_tol: float = 1e-5           # ... or when the weighted cost changes less than this, relative
    reinit_rounds: int = 5               # after the robust solve: descend the TLS objective with re-initialisation
    #                                      (LAGO / chordal) and suspect-dropping jumps until the labels settle
    reinit_max_solves: int = 10          # at most this many re-initialisations over all rounds (cost bound)
    calibrate_noise: bool = True         # scale the thresholds of those rounds by `thresholds.fence_scale` of the
    #                                      kept loops (public graphs state information 10-1000x too loose)
    fence_factor: float = 10.0           # an inlier's r^2 is within this many times the kept loops' q-quantile ...
    fence_quantile: float = 0.9          # ... (heavy tails: a high quantile, not the median)
    isolation_window: int = 5            # kept loops with no other kept loop within this many nodes at both ends get
    #                                      the standardized-residual test in those rounds (0: off)
    readmit_factor: float = 100.0        # propose re-admitting rejected loops within this factor of their threshold
    isolation_max_tests: int = 50        # at most this many per round (largest r^2 / threshold first)
    huber_k: float = 1.345               # kernel width on the whitened residual norm
    cauchy_k: float = 1.0
    loop_weighting: LoopWeighting = LoopWeighting.THRESHOLD
    probability_clip: float = 1e-3       # p is clipped to [clip, 1 - clip] before the logit
    # --- loop gate (robust modes): a loop is tested on arrival against the current estimate, in time order
    gate_loops: bool = True              # batch robust solves run the gated incremental pass first (see README)
    gate_uncertainty: bool = True        # add the odometry drift since the last loop closure to the arrival test
    gate_drift_transport: bool = False   # propagate it through the pose Jacobians (heading error -> lever arm):
    #                                      right in theory, but absurd stated heading noise (w10000: 1 rad per step)
    #                                      then opens the gate to random loops (README)
    gate_probability: float = 0.9999     # chi-square quantile of the arrival test (loop + current pose uncertainty)
    gate_factor: float = 50.0            # admit up to this many times ...
    gate_quantile: float = 0.25          # ... this quantile of the recent arrival r^2 (all gated loops)
    gate_batch_nodes: int = 50           # nodes per iSAM2 update in the batch solver's gate pass (each update costs
    #                                      a relinearisation check and one estimate; the drift in between is modelled)
    gate_window: int = 500               # number of recent arrivals in that quantile
    gate_admitted_cap: float = 1.0       # ... at most this many times that quantile of the recent admitted loops'
    #                                      r^2 (0: off; active from gate_window / 2 admitted loops): where false loops locally outnumber true ones 3:1 the arrival
    #                                      quantile is a false loop's and the level runs away (w10000 at 50 %: past
    #                                      node 6500, 2000 false loops admitted, then minutes per iSAM2 update).
    #                                      Measured on w10000 at 50 %: 1 -> 55 false admitted, 2 -> 139, 4 -> 1612
    gate_kernel_factor: float = 4.0      # online kernel width^2 <= this x the gate's quantile of arrival r^2
    gate_fallback_share: float = 0.5     # robust solve kept fewer than this share of the admitted loops: also
    #                                      solve ungated, keep the lower TLS objective
    gate_min_loops: int = 20             # until this many loops have arrived they are held (pending), then gated
    #                                      together; the final flush gates whatever has arrived on the stated model
    gate_warmup_stated: bool = False     # during that warm-up, admit at once the loops that pass the stated gate
    #                                      (the others wait): for online use with few loops already verified
    #                                      upstream (the pipeline's --incremental); off for public graphs, whose
    #                                      stated noise is too loose to tell false loops by it
    # --- iSAM2
    isam2_relinearize_threshold: float = 0.1
    isam2_relinearize_skip: int = 10
    isam2_factorization: str = "cholesky"   # or "qr" (3x slower); Cholesky stops with "indeterminate system" on
    #                                      near-singular information (CSAIL, manhattan): then iSAM2 is rebuilt with QR
    isam2_batch_nodes: int = 10          # odometry steps buffered per iSAM2 update in a full pass
    isam2_loop_kernel: RobustMode = RobustMode.CAUCHY   # online protection before the loops are classified
    isam2_final_steps: int = 2           # extra empty updates at the end of a pass (more relinearisation)

    @classmethod
    def default(cls) -> "GraphParams":
        """GNC-TLS loops, LM batch; the choice measured in `vslam bench graph` (README, section graph)."""
        return cls()

    @classmethod
    def fast(cls) -> "GraphParams":
        """Fewer iterations and a coarser GNC schedule: for previews and very large graphs."""
        return cls(lm_max_iterations=30, lm_relative_tol=1e-4, gnc_mu_step=2.0, gnc_max_iterations=40,
                   gnc_inner_iterations=5, isam2_batch_nodes=50, isam2_relinearize_skip=20)

    @classmethod
    def robust_strict(cls) -> "GraphParams":
        """Tighter inlier test (chi-square 0.95) and a slow GNC schedule: when false loops are common."""
        return cls(inlier_probability=0.95, gnc_mu_step=1.2, gnc_max_iterations=200, gnc_inner_iterations=20)

    @classmethod
    def least_squares(cls) -> "GraphParams":
        """No robust handling: every loop is trusted (for clean graphs, e.g. benchmarks without outliers)."""
        return cls(robust=RobustMode.NONE)

    def with_(self, **changes) -> "GraphParams":
        """A copy with some fields changed; strings are accepted for enum fields."""
        enums = {"solver": Solver, "robust": RobustMode, "init": InitMethod, "gnc_loss": GncLoss,
                 "gnc_impl": GncImpl, "loop_weighting": LoopWeighting, "isam2_loop_kernel": RobustMode}
        conv = {k: (enums[k](v) if k in enums and v is not None else v) for k, v in changes.items()}
        return replace(self, **conv)

    def __post_init__(self) -> None:
        if not 0.5 < self.inlier_probability < 1.0:
            raise ConfigError(f"inlier_probability must be in (0.5, 1), got {self.inlier_probability}")
        if self.gnc_mu_step <= 1.0:
            raise ConfigError(f"gnc_mu_step must be > 1, got {self.gnc_mu_step}")
        if self.isam2_batch_nodes < 1:
            raise ConfigError(f"isam2_batch_nodes must be >= 1, got {self.isam2_batch_nodes}")
        if not 0.0 < self.probability_clip < 0.5:
            raise ConfigError(f"probability_clip must be in (0, 0.5), got {self.probability_clip}")
