"""Options and tunables of the pose-graph back end, split by concern, each group a config with named presets:

- `SolverParams` (`graph.solver`): batch LM or iSAM2, the initial guess, the anchor, LM and iSAM2 settings;
- `RobustParams` (`graph.robust`): how loop closures are protected against false positives and that method's
  tunables;
- `IncrementalParams` (`graph.incremental`): how an iSAM2 pass batches its updates and protects loops online.

`GraphParams` composes the three. A scalar where a group is expected sets the group's method, so
`GraphParams(robust="huber")`, `params.replace(solver="isam2")` and `--set graph.robust=none` keep working; the
settings that used to sit flat in `GraphParams` are a ConfigError naming their new key, and a removed setting
(`RobustParams.REMOVED`: off-by-default mechanisms measured not worth turning on) a ConfigError saying why it went.
Enums carry the values used on the command line (`--robust gnc|huber|cauchy|none`, `--solver lm|isam2`).
"""
from __future__ import annotations

import dataclasses
import enum
from dataclasses import dataclass, field

from odometry.shared.config import Config, setting


class RobustMode(str, enum.Enum):
    """How loop closures are protected against false positives (odometry is always trusted)."""

    CONSENSUS = "consensus"   # local cycle consistency, then GNC-TLS over the supported loops (graph.robust; default)
    GNC = "gnc"          # gate + graduated non-convexity (truncated least squares), odometry as known inliers
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
    WARM = "warm"        # graph.gnc: warm-started inner solves, per-loop thresholds (default, see docs/graph.md)
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
class SolverParams(Config):
    """Which solver, from which initial guess, and its iteration limits (batch LM and iSAM2)."""

    SHORTHAND = "method"
    PRESETS = {
        "default": {},
        # fewer LM iterations and less frequent relinearisation: for previews and very large graphs
        "fast": {"lm_max_iterations": 30, "lm_relative_tol": 1e-4, "isam2_relinearize_skip": 20},
    }

    method: Solver = Solver.LM
    init: InitMethod = InitMethod.AUTO
    # --- batch Levenberg-Marquardt
    lm_max_iterations: int = setting(100, range="[1, inf)")
    lm_relative_tol: float = setting(1e-5, range="[0, inf)")
    lm_absolute_tol: float = setting(1e-5, range="[0, inf)")
    # --- anchor: a prior on the first node (or on the file's FIX vertices), standard deviation per axis
    anchor_sigma: float = setting(1e-6, range="(0, inf)")
    # --- linear solver of each batch LM call (graph.linear)
    direct_max_cost: float = setting(
        3e10, range="[0, inf]", unit="flops (estimated)",
        doc="an LM call whose direct Cholesky factorisation is estimated (COLAMD, symbolic elimination) above this "
            "uses PCG with a block-Jacobi preconditioner instead: graphs with many long-range loops fill in "
            "catastrophically (city10000 + 50 % random-grouped false loops: 1.5e11, 70 s a factorisation); "
            "every clean graph of the benchmark is <= 4.1e8 and every graph up to 3500 nodes at 50 % false loops "
            "<= 2.4e10 (garage), so they stay direct; 3e10 is ~10 s of factorisation here, where PCG takes "
            "~0.4 s an LM iteration on 10^4 nodes; inf: always direct")
    pcg_max_iterations: int = setting(500, range="[1, inf)", unit="CG iterations",
                                      doc="per linear solve of a PCG-solved LM step (gtsam's default)")
    pcg_relative_tol: float = setting(1e-6, range="(0, 1)", unit="x initial residual",
                                      doc="CG stops at this relative (and absolute) residual: gtsam's 1e-3 left "
                                          "LM steps too inexact to converge")
    # --- iSAM2
    isam2_relinearize_threshold: float = setting(0.1, range="[0, inf)")
    isam2_relinearize_skip: int = setting(10, range="[1, inf)")
    isam2_factorization: str = setting("cholesky", choices=("cholesky", "qr"))   # QR is 3x slower; Cholesky stops
    #                                      with "indeterminate system" on near-singular information (CSAIL,
    #                                      manhattan): then iSAM2 is rebuilt with QR


_SEE = "; see docs/graph.md"
# settings of consensus-mode mechanisms that were off by default and measured not worth turning on: naming one is a
# ConfigError saying why it went (docs/graph.md keeps each measurement)
_REMOVED = {
    "support_propagate": "off by default, measured worse: the propagated 3D cycle covariance rejected 38 true loops "
                         "of clean parking-garage (3 summed); the split calibration (calibration_split, "
                         "calibration_propagate) propagates instead" + _SEE,
    "reach_tail": "off by default, measured worse on manhattan local 50 % seed 3 (4.2 -> 4.7 cm from the clean "
                  "optimum); short spans are judged at the tail margin by short_tail_screen and readmit_short_tail"
                  + _SEE,
    "data_snooping": "off by default, measured worse: it lost a true loop on manhattan local-grouped 50 % seed 2 and "
                     "did not refuse w10000's wrong loop" + _SEE,
    "snooping_min_redundancy": "a setting of data_snooping, which was removed (off by default, measured worse)" + _SEE,
    "snooping_max_loops": "a setting of data_snooping, which was removed (off by default, measured worse)" + _SEE,
    "trial_map_covariance": "off by default, measured worse: it did not refuse w10000's wrong loop and kept one more "
                            "wrong loop on sphere2500 50 % random seed 1" + _SEE,
    "group_disputed": "off by default, measured worse on 3 of 6 ringCity random-grouped rows (50 % seed 1: 0.949 -> "
                      "7.32 m)" + _SEE,
    "group_skip_majority": "off by default, measured not worth turning on: no row changed with it at the default "
                           "calibration_propagate (48 rows), and the row it was made for passes without it" + _SEE,
    "cluster_weights": "off by default since the consensus method came in, never the better choice: the group test "
                       "(group_tests) judges a cluster as one claim" + _SEE,
    "kernel_start_always": "off by default, measured not worth turning on: where the two GNC starts agreed the "
                           "DCS-kernel start never won, and it is the costliest start" + _SEE,
    "consensus_isam2_steps": "off by default, measured worse: sphere2500 slower (local 50 % 17.6 -> 28.1 s); the "
                             "re-admission's iSAM2 steps are readmit_isam2_steps" + _SEE,
    "consensus_isam2_updates": "one iSAM2 update per GNC step: a second one re-linearised nearly every pose and cost "
                               "about one LM iteration" + _SEE,
}


@dataclass(frozen=True)
class RobustParams(Config):
    """How loop closures are protected against false positives (odometry is always trusted), and the tunables of
    each method."""

    SHORTHAND = "method"
    PRESETS = {
        # local consensus + GNC-TLS; the choice measured in `vslam bench graph` (docs/graph.md)
        "default": {},
        # a coarser GNC schedule: for previews and very large graphs
        "fast": {"gnc_mu_step": 2.0, "gnc_max_iterations": 40, "gnc_inner_iterations": 5},
        # tighter inlier test (chi-square 0.95) and a slow GNC schedule: when false loops are common
        "strict": {"inlier_probability": 0.95, "gnc_mu_step": 1.2, "gnc_max_iterations": 200,
                   "gnc_inner_iterations": 20},
        # no robust handling: every loop is trusted
        "none": {"method": "none"},
    }
    REMOVED = _REMOVED
    MOVED = {"consensus_isam2_relinearize": "readmit_isam2_relinearize",
             "consensus_isam2_max_changed": "readmit_isam2_max_changed"}

    method: RobustMode = RobustMode.CONSENSUS
    inlier_probability: float = setting(
        0.99, range="(0.5, 1)", unit="probability",
        doc="chi-square quantile of a loop's Mahalanobis residual for an inlier (per-loop threshold before the "
            "variance factor and margin); 0.99 as GTSAM's GNC and Kimera-RPGO's PCM use it: one true loop in a "
            "hundred past its quantile is what `calibration_margin` and the re-admission are there for")
    gnc_loss: GncLoss = GncLoss.TLS
    gnc_impl: GncImpl = GncImpl.WARM
    gnc_mu_step: float = setting(1.4, range="(1, inf)", doc="factor on the GNC control parameter per outer iteration")
    gnc_max_iterations: int = setting(100, range="[1, inf)", doc="outer iterations")
    gnc_inner_iterations: int = setting(5, range="[1, inf)", doc="LM iterations per outer iteration (warm-started)")
    gnc_mu_floor: float = setting(1.0, range="[0, inf)",
                                  doc="initial control parameter at least this after the gate's warm start")
    gnc_weights_tol: float = setting(1e-4, range="[0, inf)", doc="stop when weights are binary to this tolerance (TLS)")
    gnc_cost_tol: float = setting(1e-5, range="[0, inf)",
                                  doc="... or when the weighted cost changes less than this, relative")
    reinit_rounds: int = setting(5, range="[0, inf)")   # after the robust solve: descend the TLS objective with
    #                                      re-initialisation (LAGO / chordal) and suspect-dropping jumps until the
    #                                      labels settle
    reinit_max_solves: int = setting(10, range="[0, inf)",
                                     doc="at most this many re-initialisations over all rounds (cost bound)")
    calibrate_noise: bool = True         # scale the thresholds of those rounds by `thresholds.fence_scale` of the
    #                                      kept loops (public graphs state information 10-1000x too loose)
    fence_factor: float = setting(
        10.0, range="[0, inf)", unit="x r^2 quantile",
        doc="an inlier's r^2 is within this many times the kept loops' fence_quantile of r^2 (the gate's settling "
            "rounds; consensus: the short-span tail margin, graph.thresholds.tail_margin, capped by "
            "calibration_margin). 10: the same heavy-tail allowance as calibration_margin, taken on the kept loops' "
            "own residuals instead of the agreeing cycles' median ...")
    fence_quantile: float = setting(
        0.9, range="[0, 1]", unit="quantile",
        doc="... at this quantile of the kept loops' r^2: a high quantile, not the median, since real graphs' "
            "residual tails are heavy (garage's worst true loop at 22x the median), yet below 1 so one strained "
            "loop does not set the fence")
    isolation_window: int = setting(5, range="[0, inf)")   # kept loops with no other kept loop within this many
    #                                      nodes at both ends get the standardized-residual test in those rounds
    #                                      (0: off)
    readmit_factor: float = setting(100.0, range="[0, inf)",
                                    doc="propose re-admitting rejected loops within this factor of their threshold")
    isolation_max_tests: int = setting(50, range="[0, inf)",
                                       doc="at most this many per round (largest r^2 / threshold first)")
    support_window: int = setting(10, range="[0, inf)", unit="nodes",
                                  doc="loops whose both ends are within this many nodes are tested for agreement "
                                      "over the short odometry cycle between them (graph.support); 0: off")
    support_probability: float = setting(
        0.99, range="(0, 1)", unit="probability",
        doc="chi-square quantile of that cycle test: the cycle is short, so its error is the loops' noise alone and "
            "the same quantile as `inlier_probability` applies; the support only orders and starts the decision, "
            "every loop is judged again by the GNC")
    calibration_margin: float = setting(10.0, range="[0, inf)", unit="x variance factor",
                                        doc="loop thresholds = chi-square quantile x this x the variance factor of "
                                            "the agreeing cycles (graph.support; public graphs state noise 10-1000x "
                                            "too loose, the pipeline's loop poses ~2x too tight); the margin because "
                                            "residual tails of real graphs are heavier than chi-square")
    calibration_split: bool = setting(True, unit="flag",
                                      doc="3D graphs: calibrate the translation and rotation noise by separate "
                                          "variance factors of the agreeing cycles (graph.calibration) and solve on "
                                          "the calibrated information; one factor for both loosened sphere2500's "
                                          "thresholds until local false loops fit, and tightened parking-garage's "
                                          "until true loops were rejected (docs/graph.md). Planar graphs: one factor")
    calibration_propagate: int = setting(20000, range="[0, inf)", unit="cycles",
                                         doc="split calibration: propagate the covariance of up to this many agreeing "
                                             "cycles through the cycle, translation and rotation noise apart, so the "
                                             "lever arm of the rotation noise scales with the rotation factor "
                                             "(sphere2500: translation factor 0.41 summed, 0.14 propagated, 0.10 "
                                             "against ground truth); evenly spaced. The median of n cycles is off "
                                             "by ~1.1 / sqrt(n) (chi-square, 3 dof), more with a heavy tail: 5000 "
                                             "of garage's 1.2e5 gave 7.24-7.95e-5 over its random-policy draws "
                                             "(seed 3 at 30 % dropped three true loops at their thresholds' edge), "
                                             "20000 gives 7.51-7.64e-5, all 7.50-7.57e-5 (~1 s against ~9 s); 0: "
                                             "the blocks of the summed covariance")
    calibration_min_loops: int = setting(10, range="[1, inf)", unit="cycles",
                                         doc="calibrate only with at least this many agreeing cycles")
    calibration_refine: int = setting(
        5, range="[0, inf)", unit="rounds",
        doc="planar graphs: re-estimate the variance factor from the agreeing cycles that also agree on the "
            "calibrated model (cycle r^2 <= chi-square(support_probability) x calibration_margin x the factor), "
            "until it changes by < 1 % or this many rounds: the support test runs on the stated information, which "
            "on a graph stating its noise ~400x too loose lets short false loops agree with true ones (w10000 50 % "
            "local / local-grouped: 44-48 % of the agreeing pairs hold a false loop, factor 3.4-4.3x the clean "
            "graph's; it converges in 2-3 rounds, 5 is a cap); 0 = one estimate (graph.calibration.refined_factor)")
    own_cycle_test: bool = setting(True, unit="flag",
                                   doc="after the decision, a kept loop at most support_window steps apart is "
                                       "dropped when the cycle it closes with the odometry between its ends is worse "
                                       "than own_cycle_quantile of the agreeing cycles of kept loops (within [the "
                                       "chi-square quantile, its threshold]): false loops a few steps apart fit the "
                                       "global margin (sphere2500 local 50 %: 5-6 kept, 0.23-0.25 m against 0.203 m); "
                                       "graph.short_span, docs/graph.md")
    own_cycle_quantile: float = setting(1.0, range="(0, 1]", unit="probability",
                                        doc="... that quantile: the graph's own tail of short-cycle errors (2.0 x "
                                            "chi-square(0.99) on sphere2500, 10.5 x on intel, whose worst true "
                                            "short-span loop sits at 8.5 x; 0.99 put intel's at 4.2 x and lost it)")
    readmit_short_tail: bool = setting(
        True, unit="flag",
        doc="the re-admission of rejected loops that agree with a kept loop (graph.readmit) judges loops at most "
            "2 x support_window steps apart at the kept loops' own tail margin (fence_factor x their "
            "fence_quantile of r^2, graph.thresholds.tail_margin) instead of calibration_margin: over a short "
            "span no drift "
            "strain excuses a misfit, and false loops beside a true revisit agree with it and fit the global "
            "margin once back (manhattan local 50 %, seeds 1-3: every loop re-admitted was such a loop; intel's "
            "true re-admitted loops span 620-1272 steps); docs/graph.md")
    short_tail_screen: bool = setting(
        True, unit="flag",
        doc="at the end of the decision, the kept loops at most 2 x support_window steps apart are left out at once, "
            "the map re-solved without them, and they are taken back by TLS descent at the kept loops' own tail "
            "margin (as readmit_short_tail); the result stands when its TLS objective there is not higher: a loop "
            "kept from the start bends its few steps of odometry until it fits, and only the map unbent shows it "
            "(manhattan local-grouped 50 %); graph.robust, docs/graph.md")
    screen_local: bool = setting(
        True, unit="flag",
        doc="the short-tail screen offers each revisit of dropped short-span loops back with a solve over the nodes "
            "within support_window steps of its stretch only, every other pose held (graph.local_solve), instead of "
            "a whole-graph LM per offer: a loop a few steps long moves only its neighbourhood (w10000 at 50 % local: "
            "179 whole-graph solves of ~0.3 s); the objective is still compared over the whole graph; docs/graph.md")
    screen_family_bound: bool = setting(
        True, unit="flag",
        doc="the short-tail screen judges the short-span loops at the family-wise chi-square bound of the n kept "
            "loops (chi-square^-1(1 - (1 - inlier_probability) / n) x the variance factor) where that is tighter than "
            "the tail margin and the kept loops follow the calibrated model (graph.thresholds.heavy_tailed): the tail "
            "margin must hold the heaviest true tail of any graph, and lets injected loops stating the truth only "
            "roughly stay (w10000 at 50 % local: 224 kept, 0.3 m claims between poses 2 cm apart); docs/graph.md")
    readmit_rounds: int = setting(3, range="[0, inf)", unit="solves",
                                  doc="after the robust solve, admit the loops that fit at the solution and re-solve, "
                                      "at most this many times")
    readmit_max_loops: int = setting(
        50, range="[0, inf)", unit="loops",
        doc="the re-admission of rejected loops that agree with a kept loop (graph.readmit) re-solves with at most "
            "this many of them, the nearest their threshold among those within readmit_factor of it (0: no cap); "
            "a loop that fits only once back misses by a few times, the chance-supported false loops of a large "
            "graph by 10-1800x, and each in the re-solve costs fill-in and LM iterations (w10000 at 50 % random: "
            "728 candidates, 30 s of 42 s); docs/graph.md")
    trial_max_loops: int = setting(50, range="[0, inf)", unit="loops",
                                   doc="up to this many unsupported loops are tried jointly in a GNC from the solution "
                                       "(a lone true loop under drift fits only once the map moves to it); more are "
                                       "only tested at the solution: long-range loops in every inner solve cost "
                                       "minutes on 10^4-node graphs")
    readmit_isam2_steps: bool = setting(
        True, unit="flag",
        doc="on planar graphs, the GNC of the re-admission (graph.readmit: the kept loops known inliers, at most "
            "`readmit_max_loops` candidates re-weighted) takes its steps by iSAM2 updates that remove and re-add "
            "only the loops whose weight changed (graph.tls): gtsam's LM re-linearises and re-factors the whole "
            "graph for each step, iSAM2 only the cliques the changed loops and the moved poses touch (w10000 at "
            "50 % random: 12 steps, ~0.65 s each by LM under load, ~0.3 s by iSAM2); only where the step's graph is "
            "solved directly (graph.linear: iSAM2 has no iterative solver). 3D graphs keep LM (iSAM2 over Pose3 "
            "re-linearises more: sphere2500 was slower); docs/graph.md")
    readmit_isam2_gauss_newton: bool = setting(
        True, unit="flag",
        doc="`readmit_isam2_steps` by Gauss-Newton (full back-substitution) instead of Powell's dogleg: the kept "
            "loops are fixed and only the candidates re-weighted, and dogleg's step evaluates the whole graph's "
            "error (~0.2 s of a ~0.3 s step on w10000); dogleg where the other weights move too (Gauss-Newton "
            "steps of the consensus GNC took ring at 50 % random-grouped to other labels); docs/graph.md")
    readmit_isam2_relinearize: float = setting(
        0.01, range="(0, inf)", unit="rad",
        doc="iSAM2 relinearisation threshold of `readmit_isam2_steps` on a pose's rotation update (translations "
            "never call for one: a between factor is linear in them at fixed rotations); gtsam's example 0.1 "
            "tenfold tightened, since a label is decided on r^2 near its threshold")
    readmit_isam2_max_changed: int = setting(
        50, range="[0, inf)", unit="loops",
        doc="`readmit_isam2_steps`: a GNC step that changes the weights of more loops than this is taken by LM "
            "instead (iSAM2 would re-factor nearly the whole graph, in a worse ordering: 4.6 s for 3609 loops on "
            "w10000 at 50 % random, against ~0.5 s by LM); 50 = `readmit_max_loops`, the candidates of the "
            "re-admission's GNC")
    trial_forecast: bool = setting(
        True, unit="flag",
        doc="before the joint trial, run its GNC over the tried loops on the Gaussian marginal of the solved map on "
            "their end poses (graph.reduced: one partial elimination, then a GNC on a few hundred poses); when it "
            "keeps none of them the whole-graph trial (a GNC of ~13 whole-graph solves) is not run. The kept loops "
            "are held in that forecast, so a trial that would only push kept loops out is not run either "
            "(docs/graph.md)")
    group_tests: int = setting(10, range="[0, inf)", unit="clusters",
                               doc="after GNC, re-solve without each of this many kept clusters of agreeing loops "
                                   "(those nearest their thresholds first) and drop a cluster whose absence lowers "
                                   "the TLS objective: a group of consistent false loops the map bent to fits "
                                   "loop by loop (graph.robust); 0: off")
    disputed_clusters: int = setting(
        50, range="[0, inf)", unit="clusters",
        doc="after the group test, the kept clusters of 2+ loops that some start of the decision (GNC or TLS "
            "descent) rejected whole leave at once, the map is re-solved without them and each is offered back "
            "(graph.disputed); the new set stands when the TLS objective with each charged as one hypothesis is "
            "lower. Up to this many disputed clusters (more: not tested, each offer is a solve); 0: off")
    retry_clusters: int = setting(3, range="[0, inf)", unit="clusters",
                                  doc="after the group test, re-try this many supported clusters rejected whole "
                                      "(those nearest their thresholds first): all back, LM, TLS descent over the "
                                      "kept loops and them; the new set stands when the group-level TLS objective "
                                      "is lower (graph.groups.retry_rejected). A GNC start can end with a true "
                                      "revisit out while a bend elsewhere holds its loops off (ringCity "
                                      "random-grouped 30 %, seed 3: 16 true loops out, objective 4601.6 -> 4348.4 "
                                      "with them back; w10000 at 50 % local, seed 2: the five true loops closing "
                                      "its last 100 nodes, rejected whole by the winning DCS-kernel start, ATE "
                                      "0.19 -> 0.07 m with them back). 0: off (docs/graph.md)")
    retry_forecast: bool = setting(
        True, unit="flag",
        doc="the re-try of a rejected cluster (`retry_clusters`) is first made on the Gaussian marginal of the solved "
            "map on the cluster's end poses (graph.reduced.forced_descent: all its loops in, LM, TLS descent); when "
            "none of its loops survives there, the whole-graph re-try is not made (city10000 at 50 % random: three "
            "chance-agreeing false pairs, ~13 s of whole-graph LM and descent each, all dropped again); the forecast "
            "holds the kept loops fixed, so a re-try that would only push kept loops out is not made either")
    group_margin_once: bool = setting(True, doc="the group test's threshold (graph.groups.group_threshold) grants "
                                                "the heavy-tail margin (calibration_margin) once, on one loop's "
                                                "chi-square quantile, and holds the n x dof quantile to the larger "
                                                "of the variance factor and the odometry's a-posteriori one at the "
                                                "solution (never above the margin on the whole sum): a false group "
                                                "bending a stretch without true loop ends costs less than ten "
                                                "margins (ringCity random-grouped 30 %, seed 3: bend ~21.7 against "
                                                "41.5, 10.7 with it), a true revisit straining biased odometry more "
                                                "than one (tests/graph/test_consensus.py: odometry 34x the cycles' "
                                                "factor). false: the margin on the whole sum (docs/graph.md)")
    group_joint_screen: bool = setting(True, doc="before the group test's one screen per cluster, one warm solve "
                                                 "with all the tested clusters left out: those whose loops all "
                                                 "still fit there are passed (graph.robust; a cost bound, false: "
                                                 "every cluster screened on its own)")
    odometry_start: bool = setting(True, doc="also run GNC from the odometry chain; keep the lower TLS objective")
    odometry_start_short_skip: bool = setting(
        True, doc="skip the GNC from the odometry chain (and so the DCS-kernel start) when every candidate the GNC from "
                  "the supported start rejected is short-span (graph.thresholds.short_span): the odometry start exists "
                  "for a false group that bent the supported start and the long loops it strains, truncated there; "
                  "with every long-range candidate kept none was strained (city10000 at 50 % local-grouped, seed 2: "
                  "17 GNC steps, 21 s of 167 s, to the same loops and TLS objective)")
    kernel_start: bool = setting(True, doc="when some supported loop does not fit at the supported start, also start "
                                           "from a DCS-kernel solve from the odometry chain followed by TLS descent "
                                           "(graph.kernel_start); the lowest TLS objective wins")
    kernel_phi: float = setting(1.0, range="(0, inf)", unit="x variance factor",
                                doc="DCS kernel width of that start (Agarwal et al. 2013: 1) on r^2 in the loops' "
                                    "stated units times the variance factor of the agreeing cycles (public graphs "
                                    "state noise 10-1000x too loose)")
    kernel_descent_rounds: int = setting(10, range="[1, inf)", unit="solves",
                                         doc="at most this many re-solves of its TLS descent (keep the loops that "
                                             "fit, re-solve, until the set is stable)")
    confident_start: bool = setting(
        True, doc="when some supported loop does not fit at the supported start, first start from the map solved on "
                  "the confidently supported loops only (graph.confident: agreeing pairwise under the calibrated "
                  "noise, in clusters of `confident_min_cluster`) by TLS descent over every candidate; the only "
                  "start when every confident cluster keeps loops there, else one more beside the GNC starts (the "
                  "lowest TLS objective wins). Thousands of chance-supported random false loops bent every GNC "
                  "start on w10000 at 50 % (38.9 m from the clean optimum)")
    confident_misfit_max_share: float = setting(
        0.01, range="[0, 1]", unit="share of the confident clusters",
        doc="where a solve over every candidate stays direct (no `cluster_start`), the confident start is skipped "
            "when more than this share of the confident clusters misfit whole at the map of the confident loops "
            "(no loop of the cluster within its threshold): consistent false groups among the confident loops bent "
            "that map, so it cannot stand alone and the GNC starts decide, as on the costly path. Its TLS descent "
            "creeps there (city10000 at 50 % local-grouped, seed 2: 10 re-solves, 118 s of 167 s, TLS objective "
            "26163 against the supported start's 23295, which won). A map of true revisits misfits a stray cluster "
            "or two (city10000 at 50 % local: 0 and 2 of ~1130, 0.002), a bent one hundreds (city10000 "
            "local-grouped 0.33, w10000 local / local-grouped 0.11-0.14; seeds 1 and 2); the value is the one "
            "`core_alone_max_split` uses for the same question; 1: never skipped")
    cluster_start: bool = setting(
        True, doc="when the confident start does not stand alone and a solve over every candidate loop would need "
                  "the iterative solver (its direct factorisation estimated above `solver.direct_max_cost`), decide "
                  "over clusters of agreeing loops on a reduced graph (one representative loop per cluster, "
                  "graph.cluster_start) instead of the GNC starts over every candidate: groups of consistent false "
                  "loops between distant places fill in every such solve (city10000 at 50 % random-grouped: "
                  "160-290 s, w10000 not finished in 13 min)")
    cluster_direct_max_cost: float = setting(
        1e10, range="[0, inf]", unit="flops (estimated)",
        doc="the reduced graph of `cluster_start` is solved by PCG when its direct factorisation is estimated above "
            "this (its GNC steps are two warm LM iterations each, where PCG's slower convergence costs little): "
            "w10000 at 50 % random-grouped, 1.6e10: 13-17 s a step direct, ~3.7 s PCG (loaded machine); city10000 "
            "at 50 % random-grouped, 1.4e9, stays direct (0.3-0.7 s a step)")
    cluster_representatives: int = setting(
        1, range="[1, inf)", unit="loops per cluster",
        doc="loops standing for each cluster on the reduced graph of `cluster_start` (1: its middle loop; 2 or "
            "more: spread evenly from its first to its last loop in time, each with an even share of the cluster's "
            "information and threshold). One edge per cluster lets the reduced GNC fit a false group by a kink of "
            "the odometry at its ends that the group's ten parallel loops would resist (docs/graph.md)")
    cluster_zero_weights: bool = setting(
        True, doc="in the GNC over clusters on the reduced graph of `cluster_start`, a representative whose weight "
                  "is below `gnc_weights_tol` (where the stopping test already counts a weight as 0) leaves the "
                  "step's graph instead of staying in it at that weight (graph.tls.gnc_tls). Far from the convex "
                  "start such loops pull by ~sqrt(mu c^2) each whatever their residual, and as long-range edges "
                  "fill in every step: city10000 at 50 % random-grouped, the GNC from the odometry chain held 2053 "
                  "of 2206 representatives below it at its first step; 7.1 -> 2.5 s CPU, and seed 1's decision "
                  "there keeps no false cluster instead of 8 (docs/graph.md). false: the floor of every other GNC, "
                  "1e-9")
    cluster_decided_alone: bool = setting(
        True, doc="with `cluster_start`, where the first reduced GNC's kept clusters do not fill in and at most "
                  "`core_alone_max_split` of the clusters are undecided at its map (a kept one with a loop "
                  "misfitting, a rejected one with a loop fitting: graph.cluster_start.undecided_share), the other "
                  "reduced GNC is skipped; on a reduced graph solved directly the odometry chain's GNC goes first "
                  "then (city10000 at 50 % random-grouped: every cluster decided right from it, 0 undecided, "
                  "against 0.32-0.33 from the representatives' LAGO, whose GNC cost 9.4 s CPU of the stage's 16)")
    core_start: bool = setting(
        True, doc="where the reduced decision of `cluster_start` keeps clusters whose loops fill in themselves (above "
                  "`solver.direct_max_cost`: false groups it kept), also grow a start from the largest confident "
                  "clusters down by size class (graph.core_start) and keep whichever map has the lower TLS objective "
                  "over every candidate: the reduced graph fits a false group's one edge by a kink of the odometry "
                  "that its ten loops resist (w10000 at 50 % random-grouped: not finished in 10 minutes without it, "
                  "176-191 s with it, every true loop kept, no wrong loop)")
    core_alone: bool = setting(
        True, doc="with `core_start`: run the reduced GNC from the representatives' LAGO / chordal first; where its "
                   "kept clusters fill in, grow the core at once, and where the core's map is decisive (at most "
                   "`core_alone_max_split` of the confident clusters outside it split there) and has the lower TLS "
                   "objective over every loop, it is the start and the reduced GNC from the odometry chain is "
                   "skipped (w10000 at 50 % random-grouped: 63 s of ~100 s). Else as without it")
    core_alone_max_split: float = setting(
        0.01, range="[0, 1]", unit="share of the confident clusters outside the core",
        doc="`core_alone` takes the core's map alone only when at most this share of the confident clusters with "
            "candidates outside the core split there (some loops fit, some not): a map that explains the loops fits "
            "a true revisit whole and misfits a false group whole (w10000 at 50 % random-grouped, seed 1: 0.0002); "
            "a core that leaves revisits loose splits them (city10000, seed 1, clusters of 16+: 0.074)")
    core_max_cost: float = setting(
        1e9, range="[0, inf]", unit="flops (estimated)",
        doc="the core of `core_start` stops growing before a size class whose core's direct factorisation is "
            "estimated above this: a map of revisits fills in like a clean graph (every clean graph of the benchmark "
            "<= 4.1e8), the long-range false groups entering make it jump (w10000 at 50 % random-grouped, clusters "
            "of 16+ -> 8+: 9.6e7 -> 1.7e10; city10000: 1.8e7 -> 5.3e9)")
    confident_min_cluster: int = setting(3, range="[2, inf)", unit="loops",
                                         doc="smallest cluster of calibrated-agreeing loops that counts as "
                                             "confident: a true revisit yields a run of consecutive agreeing loops, "
                                             "while two random false loops agree by chance (w10000 at 50 % random, "
                                             "calibrated: 54 false loops in agreeing pairs or larger, 8 in clusters "
                                             "of 3 or more, all beside true loops they agree with)")
    # the final polish (graph.polish) once the loop set is decided
    polish_max_steps: int = setting(5, range="[0, inf)", unit="Gauss-Newton steps",
                                    doc="at most this many Gauss-Newton steps with the kept loops after the robust "
                                        "solve, from its estimate (LM stops at its cost tolerance, which on a flat "
                                        "objective leaves the map far from the optimum: w10000 0.56 m); 0: off")
    polish_backtracks: int = setting(
        10, range="[0, inf)", unit="halvings",
        doc="a polish step that raises the cost is halved up to this many times before the polish stops (a step "
            "scaled by 2^-10 that still raises the cost is no descent direction worth taking); 0: the first "
            "such step ends the polish (w10000 at 50 % random-grouped, seed 1: every label right, the undamped "
            "first step raised the cost, the map stayed 0.67 m from the optimum); graph.polish")
    polish_step_tol: float = setting(1e-5, range="[0, inf)", unit="x map extent",
                                     doc="the polish stops after a step that moves no node by more than this x the "
                                         "largest side of the map's bounding box (at 1e-3 garage stopped 0.22 mm "
                                         "from the optimum after a 3.6 cm step; at 1e-5, 2e-6 m for one more step)")
    huber_k: float = setting(1.345, range="(0, inf)", doc="kernel width on the whitened residual norm")
    cauchy_k: float = setting(1.0, range="(0, inf)")
    loop_weighting: LoopWeighting = setting(
        LoopWeighting.THRESHOLD,
        doc="how a loop's P(loop | score) from the loop detector enters (graph files carry none: no effect there): "
            "threshold shifts its inlier threshold by 2 logit(p), the Bayesian test of the hypothesis against its "
            "alternative; a probability is evidence about the claim, not about the measurement noise")
    probability_clip: float = setting(
        1e-3, range="(0, 0.5)", unit="probability",
        doc="p is clipped to [clip, 1 - clip] before the logit: the shift stays within +-13.8 (2 logit(0.999)), so "
            "no calibrated score makes a loop certain either way")
    # --- loop gate (robust modes): a loop is tested on arrival against the current estimate, in time order
    gate_loops: bool = True              # batch robust solves run the gated incremental pass first (see docs/graph.md)
    gate_uncertainty: bool = True        # add the odometry drift since the last loop closure to the arrival test
    gate_drift_transport: bool = False   # propagate it through the pose Jacobians (heading error -> lever arm):
    #                                      right in theory, but absurd stated heading noise (w10000: 1 rad per step)
    #                                      then opens the gate to random loops (docs/graph.md)
    gate_probability: float = setting(0.9999, range="(0, 1)",
                                      doc="chi-square quantile of the arrival test (loop + current pose uncertainty)")
    gate_factor: float = setting(50.0, range="[0, inf)", doc="admit up to this many times ...")
    gate_quantile: float = setting(0.25, range="[0, 1]",
                                   doc="... this quantile of the recent arrival r^2 (all gated loops)")
    gate_window: int = setting(500, range="[1, inf)", doc="number of recent arrivals in that quantile")
    gate_admitted_cap: float = setting(1.0, range="[0, inf)")   # ... at most this many times that quantile of the
    #                                      recent admitted loops' r^2 (0: off; active from gate_window / 2 admitted
    #                                      loops): where false loops locally outnumber true ones 3:1 the arrival
    #                                      quantile is a false loop's and the level runs away (w10000 at 50 %: past
    #                                      node 6500, 2000 false loops admitted, then minutes per iSAM2 update).
    #                                      Measured on w10000 at 50 %: 1 -> 55 false admitted, 2 -> 139, 4 -> 1612
    gate_kernel_factor: float = setting(4.0, range="[0, inf)",
                                        doc="online kernel width^2 <= this x the gate's quantile of arrival r^2")
    gate_fallback_share: float = setting(0.5, range="[0, 1]")   # robust solve kept fewer than this share of the
    #                                      admitted loops: also solve ungated, keep the lower TLS objective
    gate_min_loops: int = setting(20, range="[0, inf)")   # until this many loops have arrived they are held
    #                                      (pending), then gated together; the final flush gates whatever has arrived
    #                                      on the stated model
    gate_warmup_stated: bool = False     # during that warm-up, admit at once the loops that pass the stated gate
    #                                      (the others wait): for online use with few loops already verified
    #                                      upstream (the pipeline's --incremental); off for public graphs, whose
    #                                      stated noise is too loose to tell false loops by it
    # h14-core: the consensus solve's own GNC schedule (graph.robust). Its starts already carry the loop
    # corrections, so a coarse schedule reaches the same labels: measured on the tuning half (ring, intel, seed 1),
    # mu step 2 / 2 inner iterations gave the same loops and ATE as 1.4 / 5 in half the time (docs/graph.md)
    consensus_mu_step: float = setting(2.0, range="(1, inf)", unit="x per outer step",
                                       doc="factor on the GNC control parameter per outer step (consensus mode)")
    consensus_inner_iterations: int = setting(2, range="[1, inf)", unit="LM iterations",
                                              doc="warm-started LM iterations per GNC outer step (consensus mode); "
                                                  "also caps the least-squares solve of the supported-loop start")
    consensus_binary_converge: bool = setting(
        True, doc="once every GNC weight is binary (0 or 1), solve each further outer step to convergence instead "
                  "of `consensus_inner_iterations`: the steps left are then a TLS descent, and with a few warm "
                  "iterations per step it moved by a few dozen labels per step for 40+ steps (city10000 at 50 % "
                  "random-grouped false loops) until the map settled")


# What each robust setting is, for the reader deciding what to touch (docs/graph.md, "Tunables"). Only the
# `decision` settings define the model a loop is judged by; every `budget` bounds work and every `mechanism` switches
# a step measured on the benchmark (on or off as its doc says why), and `other_methods` belong to the non-default
# methods (arrival gate, settling rounds of the GNC mode, M-estimators). tests/graph/test_params.py keeps this a
# partition of the fields.
ROBUST_KINDS: dict[str, tuple[str, ...]] = {
    "decision": ("method", "inlier_probability", "support_window", "support_probability", "calibration_margin",
                 "confident_min_cluster", "fence_factor", "fence_quantile", "own_cycle_quantile", "kernel_phi",
                 "loop_weighting", "probability_clip"),
    "budget": ("gnc_mu_step", "gnc_max_iterations", "gnc_inner_iterations", "gnc_mu_floor", "gnc_weights_tol",
               "gnc_cost_tol", "consensus_mu_step", "consensus_inner_iterations", "calibration_propagate",
               "calibration_min_loops", "calibration_refine", "readmit_rounds", "readmit_max_loops", "trial_max_loops",
               "group_tests", "disputed_clusters", "retry_clusters", "kernel_descent_rounds", "confident_misfit_max_share",
               "cluster_direct_max_cost", "cluster_representatives", "core_alone_max_split", "core_max_cost",
               "polish_max_steps", "polish_backtracks", "polish_step_tol", "readmit_isam2_relinearize",
               "readmit_isam2_max_changed"),
    "mechanism": ("gnc_loss", "gnc_impl", "calibrate_noise", "calibration_split", "own_cycle_test",
                  "readmit_short_tail", "short_tail_screen", "screen_local", "screen_family_bound",
                  "readmit_isam2_steps", "readmit_isam2_gauss_newton", "trial_forecast", "retry_forecast",
                  "group_margin_once", "group_joint_screen", "odometry_start", "odometry_start_short_skip",
                  "kernel_start", "confident_start", "cluster_start", "cluster_zero_weights", "cluster_decided_alone",
                  "core_start", "core_alone", "consensus_binary_converge"),
    "other_methods": ("reinit_rounds", "reinit_max_solves", "isolation_window", "readmit_factor",
                      "isolation_max_tests", "huber_k", "cauchy_k", "gate_loops", "gate_uncertainty",
                      "gate_drift_transport", "gate_probability", "gate_factor", "gate_quantile", "gate_window",
                      "gate_admitted_cap", "gate_kernel_factor", "gate_fallback_share", "gate_min_loops",
                      "gate_warmup_stated"),
}


@dataclass(frozen=True)
class IncrementalParams(Config):
    """How an iSAM2 pass (the pipeline's --incremental, `--solver isam2`, the gate pass) batches its updates and
    protects loops before they are classified."""

    PRESETS = {
        "default": {},
        # fewer, larger iSAM2 updates: for previews and very large graphs
        "fast": {"batch_nodes": 50},
    }

    batch_nodes: int = setting(10, range="[1, inf)", unit="nodes",
                               doc="odometry steps buffered per iSAM2 update in a full pass")
    loop_kernel: RobustMode = RobustMode.CAUCHY   # online protection before the loops are classified
    final_steps: int = setting(2, range="[0, inf)", unit="updates",
                               doc="extra empty updates at the end of a pass (more relinearisation) when the "
                                   "pass reports its own estimate (robust methods other than consensus, whose "
                                   "final poses come from the batch decision)")
    gate_batch_nodes: int = setting(50, range="[1, inf)")   # nodes per iSAM2 update in the batch solver's gate pass
    #                                      (each update costs a relinearisation check and one estimate; the drift in
    #                                      between is modelled)


_MOVED = {name: f"{group}.{new or name}" for group, names in (
    ("solver", ("init", "lm_max_iterations", "lm_relative_tol", "lm_absolute_tol", "anchor_sigma",
                "isam2_relinearize_threshold", "isam2_relinearize_skip", "isam2_factorization")),
    ("incremental", (("isam2_batch_nodes", "batch_nodes"), ("isam2_loop_kernel", "loop_kernel"),
                     ("isam2_final_steps", "final_steps"), "gate_batch_nodes")),
    ("robust", tuple(f.name for f in dataclasses.fields(RobustParams) if f.name != "method")),
) for name, new in ((n, None) if isinstance(n, str) else n for n in names)}


@dataclass(frozen=True)
class GraphParams(Config):
    """Every tunable of the back end, by concern. Start from a preset (`GraphParams.preset("fast")`) and `replace`
    single groups or fields (`p.replace(robust={"huber_k": 2.0})`, `p.replace(solver="isam2")`); strings are
    accepted for enum fields."""

    MOVED = _MOVED
    REMOVED = _REMOVED       # flat keys too: a removed robust setting is no unknown key at either level
    PRESETS = {
        # local consensus + GNC-TLS, LM batch; the choice measured in `vslam bench graph` (docs/graph.md)
        "default": {},
        # fewer iterations and a coarser GNC schedule: for previews and very large graphs
        "fast": {"solver": SolverParams.PRESETS["fast"], "robust": RobustParams.PRESETS["fast"],
                 "incremental": IncrementalParams.PRESETS["fast"]},
        # tighter inlier test (chi-square 0.95) and a slow GNC schedule: when false loops are common
        "robust_strict": {"robust": RobustParams.PRESETS["strict"]},
        # no robust handling: every loop is trusted (for clean graphs, e.g. benchmarks without outliers)
        "least_squares": {"robust": RobustParams.PRESETS["none"]},
    }

    solver: SolverParams = field(default_factory=SolverParams)
    robust: RobustParams = field(default_factory=RobustParams)
    incremental: IncrementalParams = field(default_factory=IncrementalParams)
