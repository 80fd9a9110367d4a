"""Incremental (online) pose graph on iSAM2, with the same add_* calls as the batch `PoseGraph`.

What an online system needs, and what this does:
- odometry arrives every frame: nodes and factors are buffered and handed to iSAM2 every `isam2_batch_nodes`
  nodes (or on `update()`), because one iSAM2 update per pose costs a Python round trip and a relinearisation
  check each time (gtsam notes: 71 s for w10000 at one update per pose);
- the estimate is computed only when asked (`estimate()`, `pose(id)`), and cached until the next update;
- a false loop must not bend the map before it is recognised. Robust modes gate each loop on arrival: its
  squared Mahalanobis residual against the current estimate must stay below `gate_factor` x its inlier threshold x
  the running residual scale of admitted loops; loops that fail are deferred, not dropped. Admitted loops enter
  iSAM2 behind an M-estimator (`isam2_loop_kernel`, Cauchy by default). `classify_loops()` runs the batch robust
  solve (GNC) warm-started from the current estimate, re-tests the deferred loops, removes rejected loops from
  iSAM2 and inserts the loops that became inliers;
- a node without a guess is placed by composing odometry from a node already placed.
"""
from __future__ import annotations

import time
from collections import deque

import gtsam
import numpy as np
from scipy.stats import chi2

from graph.batch import build, mestimator_weights, solve
from graph.factors import (
    NoiseCache,
    array_from_values,
    from_pose,
    graph_of,
    gtsam_information,
    squared_residuals,
    to_pose,
    values_from_array,
)
from graph.ids import id_array
from graph.model import POSE_WIDTH, TANGENT_DIM, PoseGraphData, checked_edge, information_from
from graph.params import GraphParams, InitMethod, RobustMode, Solver
from graph.result import GraphResult
from graph.thresholds import loop_thresholds

PENDING, ADMITTED, DEFERRED, REJECTED = 0, 1, 2, 3


def _isam_params(params: GraphParams, factorization: str) -> gtsam.ISAM2Params:
    p = gtsam.ISAM2Params()
    p.setRelinearizeThreshold(params.solver.isam2_relinearize_threshold)
    p.relinearizeSkip = params.solver.isam2_relinearize_skip
    p.setFactorization(factorization.upper())
    return p


class IncrementalPoseGraph:
    """Online pose graph. Node ids are arbitrary ints; an edge (i, j, delta) measures delta = x_i^-1 x_j."""

    def __init__(self, dim: int = 2, params: GraphParams | None = None):
        if dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {dim}")
        self.dim = dim
        self.params = params or GraphParams()
        self._factorization = self.params.solver.isam2_factorization
        self._isam = gtsam.ISAM2(_isam_params(self.params, self._factorization))
        self._trusted: list = []                      # prior and odometry factors handed to iSAM2 (for a rebuild)
        self._noise = NoiseCache(dim)
        self._between = gtsam.BetweenFactorPose2 if dim == 2 else gtsam.BetweenFactorPose3
        self._ids: list[int] = []
        self._key: dict[int, int] = {}
        self._guess: list[np.ndarray | None] = []
        self._in_isam: list[bool] = []
        self._pending_nodes: list[int] = []           # keys
        self._pending_factors: list = []              # priors and odometry
        self._pending_loops: list[int] = []           # loop indices
        self._edges: list[tuple[int, int, np.ndarray, np.ndarray, bool, float]] = []
        self._loop_edge: list[int] = []
        self._loop_factor: list = []                  # Gaussian factor of each loop (residual tests, re-insertion)
        self._loop_slot: list[int] = []               # iSAM2 factor index, -1 when not in iSAM2
        self._loop_robust: list[bool] = []            # in iSAM2 behind the kernel (not yet classified)
        self._loop_state: list[int] = []
        self._loop_c2: list[float] = []
        self._arrival_r2: deque[float] = deque(maxlen=self.params.robust.gate_window)
        # arrival r^2 of admitted loops
        self._admitted_r2: deque[float] = deque(maxlen=self.params.robust.gate_window)
        self._gating = self.params.robust.gate_loops and self.params.robust.method != RobustMode.NONE
        self._c2_cache: dict[float, float] = {}
        dof = TANGENT_DIM[dim]
        self._c2_base = float(chi2.ppf(self.params.robust.inlier_probability, dof))
        self._gate_extra = float(chi2.ppf(self.params.robust.gate_probability, dof)
                                 - chi2.ppf(self.params.robust.inlier_probability, dof))
        self._info_ok: dict[bytes, np.ndarray] = {}
        self._drift: list = []                        # per node: first odometry link (older key, Ad, cov) or None
        self._since: dict[int, np.ndarray] = {}       # drift covariance since the last loop closure (memo)
        self._tied: set[int] = {0}                    # nodes tied to the map by an admitted loop (and the anchor)
        self._gate_c2: list[float] = []
        self._held: list[int] = []                    # loops waiting for the gate's warm-up
        self._counted: set[int] = set()
        self._parent: list[int] = []                 # union-find over nodes linked by odometry / admitted loops
        self._estimate: gtsam.Values | None = None
        self.notes: list[str] = []
        self.updates = 0
        self.seconds = 0.0                            # wall time inside iSAM2 and the gate

    # ------------------------------------------------------------------------------------------- building
    def add_node(self, node_id: int, guess: np.ndarray | None = None) -> None:
        """A new pose; without a guess it is placed by the first odometry edge that links it to a placed node.

        When `isam2_batch_nodes` nodes are waiting and all are placed, they go to iSAM2 first (they have had their
        edges); otherwise buffering continues until they are."""
        node_id = int(node_id)
        if node_id in self._key:
            raise ValueError(f"node {node_id} already exists")
        if len(self._pending_nodes) >= self.params.incremental.batch_nodes and \
                all(self._guess[k] is not None for k in self._pending_nodes):
            self.update()
        k = len(self._ids)
        self._key[node_id] = k
        self._ids.append(node_id)
        g = None if guess is None else np.asarray(guess, float).reshape(POSE_WIDTH[self.dim])
        if g is not None and not np.all(np.isfinite(g)):
            raise ValueError(f"node {node_id}: guess must be finite")
        if k == 0:
            anchor = to_pose(self.dim, g) if g is not None else (gtsam.Pose2() if self.dim == 2 else gtsam.Pose3())
            g = from_pose(self.dim, anchor)
            nm = gtsam.noiseModel.Isotropic.Sigma(TANGENT_DIM[self.dim], self.params.solver.anchor_sigma)
            prior = gtsam.PriorFactorPose2 if self.dim == 2 else gtsam.PriorFactorPose3
            self._pending_factors.append(prior(0, anchor, nm))
        self._guess.append(g)
        self._in_isam.append(False)
        self._pending_nodes.append(k)
        self._parent.append(k)
        self._drift.append(None)

    def placed(self, node_id: int) -> bool:
        """Whether the node has a pose to start from (its guess, or one composed from odometry)."""
        return self._guess[self._key[int(node_id)]] is not None

    def place(self, node_id: int, guess: np.ndarray) -> None:
        """Give a node that odometry has not placed (e.g. a file vertex linked only to later nodes) its guess."""
        k = self._key[int(node_id)]
        if self._guess[k] is not None:
            raise ValueError(f"node {int(node_id)} is already placed")
        g = np.asarray(guess, float).reshape(POSE_WIDTH[self.dim])
        if not np.all(np.isfinite(g)):
            raise ValueError(f"node {int(node_id)}: guess must be finite")
        self._guess[k] = g.copy()

    def _find(self, k: int) -> int:
        root = k
        while self._parent[root] != root:
            root = self._parent[root]
        while self._parent[k] != root:
            self._parent[k], k = root, self._parent[k]
        return root

    def _union(self, a: int, b: int) -> bool:
        ra, rb = self._find(a), self._find(b)
        if ra == rb:
            return False
        self._parent[max(ra, rb)] = min(ra, rb)
        return True

    def add_odometry(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                     information: np.ndarray | None = None) -> int:
        """Odometry edge i -> j (always trusted); returns the edge index. Places an unplaced endpoint."""
        ki, kj, z, info = self._edge_args(i, j, delta, cov, information)
        if self._guess[kj] is None and self._guess[ki] is not None:
            self._guess[kj] = from_pose(self.dim, self._current(ki).compose(to_pose(self.dim, z)))
        elif self._guess[ki] is None and self._guess[kj] is not None:
            self._guess[ki] = from_pose(self.dim, self._current(kj).compose(to_pose(self.dim, z).inverse()))
        self._union(ki, kj)
        self._track_drift(ki, kj, z, info)
        e = len(self._edges)
        self._edges.append((ki, kj, z, info, False, float("nan")))
        self._pending_factors.append(self._between(ki, kj, to_pose(self.dim, z), self._noise(info)))
        return e

    def add_loop(self, i: int, j: int, delta: np.ndarray, cov: np.ndarray | None = None,
                 probability: float | None = None, information: np.ndarray | None = None) -> int:
        """Loop closure i -> j with P(loop) from the loop model (None: unknown); returns the loop index."""
        ki, kj, z, info = self._edge_args(i, j, delta, cov, information)
        p = float("nan") if probability is None else float(probability)
        if not (np.isnan(p) or 0.0 <= p <= 1.0):
            raise ValueError(f"loop probability must be in [0, 1], got {p}")
        slot = len(self._loop_edge)
        self._loop_edge.append(len(self._edges))
        self._edges.append((ki, kj, z, info, True, p))
        self._loop_factor.append(self._between(ki, kj, to_pose(self.dim, z), self._noise(info)))
        self._loop_slot.append(-1)
        self._loop_robust.append(False)
        self._loop_state.append(PENDING)
        self._loop_c2.append(self._threshold(p))
        self._gate_c2.append(self._loop_c2[-1] + self._gate_extra)
        self._pending_loops.append(slot)
        return slot

    def _threshold(self, p: float) -> float:
        key = -1.0 if np.isnan(p) else p
        c2 = self._c2_cache.get(key)
        if c2 is None:
            c2 = self._c2_cache[key] = float(loop_thresholds(np.array([p]), TANGENT_DIM[self.dim], self.params)[0])
        return c2

    def _track_drift(self, ki: int, kj: int, z: np.ndarray, info: np.ndarray) -> None:
        """Remember the first odometry link of a node to an older one: (older key, Ad(z^-1), odometry covariance)."""
        if not self._gating:
            return
        zp = to_pose(self.dim, z)
        if kj < ki:                                    # orient the edge older -> newer
            ki, kj, zp = kj, ki, zp.inverse()
        if self._drift[kj] is not None:
            return
        q = np.linalg.inv(gtsam_information(self.dim, info))
        transport = self.params.robust.gate_drift_transport
        ad = np.asarray(zp.inverse().AdjointMap(), float) if transport else np.eye(len(q))
        self._drift[kj] = (ki, ad, q)

    def _edge_args(self, i, j, delta, cov, information):
        i, j, z = checked_edge(i, j, delta, self._key, self.dim)
        m = np.asarray(information if cov is None else cov, float)
        key = m.tobytes() + (b"c" if cov is not None else b"i")
        info = self._info_ok.get(key)            # validation and inversion once per distinct matrix
        if info is None:
            info = information_from(cov, information, TANGENT_DIM[self.dim])
            if len(self._info_ok) < 10000:
                self._info_ok[key] = info
        return self._key[i], self._key[j], z, info

    def _robust(self, factor):
        """The loop factor behind the online kernel. Its width follows the arrival residuals: a kernel of width 1 in
        the stated units does nothing where the stated information is far looser than the data (w10000: residuals
        ~0.05 whitened), and admitted false loops would bend the online map; so width^2 = min(k^2,
        `gate_kernel_factor` x lower quartile of the recent arrival r^2)."""
        mode = self.params.robust.method
        if mode == RobustMode.GNC:
            mode = self.params.incremental.loop_kernel
        if mode not in (RobustMode.CAUCHY, RobustMode.HUBER):
            return factor
        k = self.params.robust.cauchy_k if mode == RobustMode.CAUCHY else self.params.robust.huber_k
        if self._gating and len(self._arrival_r2) >= self.params.robust.gate_min_loops:
            q = float(np.quantile(np.fromiter(self._arrival_r2, float), self.params.robust.gate_quantile))
            k = min(k, float(np.sqrt(self.params.robust.gate_kernel_factor * q)))
        k = max(k, 1e-6)
        est = (gtsam.noiseModel.mEstimator.Cauchy.Create(k) if mode == RobustMode.CAUCHY
               else gtsam.noiseModel.mEstimator.Huber.Create(k))
        return factor.cloneWithNewNoiseModel(gtsam.noiseModel.Robust.Create(est, factor.noiseModel()))

    def _current(self, k: int):
        """Best available pose of key k: the iSAM2 estimate once inserted, else its guess."""
        if self._in_isam[k]:
            if self._estimate is not None:
                return self._estimate.atPose2(k) if self.dim == 2 else self._estimate.atPose3(k)
            return self._isam.calculateEstimatePose2(k) if self.dim == 2 else self._isam.calculateEstimatePose3(k)
        if self._guess[k] is None:
            raise ValueError(f"node {self._ids[k]} has no initial guess and no odometry edge from a placed node")
        return to_pose(self.dim, self._guess[k])

    # ---------------------------------------------------------------------------------------------- gating
    def gate_level(self, final: bool = False) -> float | None:
        """Empirical arrival-residual level: `gate_factor` x the `gate_quantile` quantile of the arrival r^2 of the
        latest gated loops, admitted or not. A quantile of all arrivals needs no decision to be right first (a level
        fed only by admitted loops drifts up once false loops get in); a low quantile holds while fewer than 75 % of
        the recent loops are false, which happens locally even at 33 % overall (garage: false loops arrive before
        the first revisit). Arrival residuals of true loops span 1-2 decades above their lower quartile (docs/graph.md).
        None while fewer than `gate_min_loops` loops have arrived (they wait); at a final flush whatever has arrived
        is used (inf, the stated model alone, below 3 loops)."""
        n = len(self._arrival_r2)
        if n < self.params.robust.gate_min_loops and not final:
            return None
        if n < 3:
            return float("inf")
        rp = self.params.robust
        q = float(np.quantile(np.fromiter(self._arrival_r2, float), rp.gate_quantile))
        if rp.gate_admitted_cap and len(self._admitted_r2) >= rp.gate_window // 2:
            # only with a long admitted history: on a few dozen loops it ratchets the gate tight (CSAIL)
            q = min(q, rp.gate_admitted_cap * float(np.quantile(np.fromiter(self._admitted_r2, float),
                                                                rp.gate_quantile)))
        return rp.gate_factor * q

    def _uncertainty(self, k: int) -> np.ndarray:
        """Odometry drift of node k since the robot last closed a loop (gtsam tangent order): the covariance of
        the odometry chain back to the latest node tied to the map by an admitted loop (or the anchor), carried
        into k's frame. This, not the global marginal, is what a true loop's residual has to allow for: the
        marginal of a node far from the anchor is dominated by uncertainty the loop's two ends share, and would
        let random loops through (measured on w10000, docs/graph.md)."""
        chain = []
        while k not in self._since:
            link = self._drift[k]
            if link is None or k in self._tied:
                self._since[k] = np.zeros((TANGENT_DIM[self.dim],) * 2)
                break
            chain.append(k)
            k = link[0]
        cov = self._since[k]
        for k in reversed(chain):
            _, ad, q = self._drift[k]
            cov = ad @ cov @ ad.T + q
            self._since[k] = cov
        return cov

    def _tie(self, s: int) -> None:
        """An admitted loop ties its newer end to the map: drift restarts there."""
        k = max(self._edges[self._loop_edge[s]][:2])
        self._tied.add(k)
        for j in [j for j in self._since if j >= k]:
            del self._since[j]

    def _arrival_residual(self, s: int, memo_pose: dict) -> float:
        """Squared residual of loop s against the current estimate, over the loop's covariance plus the drift of
        its newer end since the last loop closure."""
        ki, kj = self._edges[self._loop_edge[s]][:2]
        v = gtsam.Values()
        for k in (ki, kj):
            if k not in memo_pose:
                memo_pose[k] = self._current(k)
            v.insert(k, memo_pose[k])
        f = self._loop_factor[s]
        if not self.params.robust.gate_uncertainty:
            return 2.0 * f.error(v)
        e = np.asarray(f.unwhitenedError(v), float)
        if kj >= ki:
            sig = self._uncertainty(kj)
        else:                                  # perturbing x_i on the right moves the error by -Ad(z^-1)
            ad = np.asarray(f.measured().inverse().AdjointMap(), float)
            sig = ad @ self._uncertainty(ki) @ ad.T
        cov = np.asarray(f.noiseModel().covariance(), float) + sig
        try:
            return float(e @ np.linalg.solve(cov, e))
        except np.linalg.LinAlgError:
            return float("inf")

    def _gate(self, slots: list[int], final: bool = False) -> list[int]:
        """Admitted subset of `slots` (plus loops held from earlier updates); the rejected ones become DEFERRED,
        and while the level is unknown (warm-up) the loops are held for the next update."""
        if not self._gating:
            for s in slots:
                self._union(*self._edges[self._loop_edge[s]][:2])
            return slots
        slots = self._held + slots
        self._held = []
        memo_pose: dict[int, object] = {}
        old = {k for s in slots for k in self._edges[self._loop_edge[s]][:2] if self._in_isam[k]}
        if len(old) > 8 and self._estimate is None:
            # single-pose estimates cost a partial back-substitution each; past a few, one full estimate is cheaper
            self._estimate = self._isam.calculateEstimate()
        admitted, measured = [], []
        for s in slots:
            ki, kj = self._edges[self._loop_edge[s]][:2]
            if self._find(ki) != self._find(kj):
                # the only link between two parts of the graph: it cannot be checked, and without it the
                # system is indeterminate (files whose consecutive ids are not always linked by odometry)
                self._union(ki, kj)
                admitted.append(s)
                continue
            r2 = self._arrival_residual(s, memo_pose)
            if s not in self._counted:
                self._counted.add(s)
                self._arrival_r2.append(r2)
            measured.append((s, r2))
        level = self.gate_level(final)
        if level is None:
            if not self.params.robust.gate_warmup_stated:
                self._held = [s for s, _ in measured]
                return admitted
            self._held = [s for s, r2 in measured if r2 > self._gate_c2[s]]
            measured = [(s, r2) for s, r2 in measured if r2 <= self._gate_c2[s]]
            level = float("inf")
        for s, r2 in measured:
            # never looser than the stated model (gate_c2), tightened to the empirical level; a loop's probability
            # shifts both through its threshold
            if r2 <= min(self._gate_c2[s], level * self._loop_c2[s] / self._c2_base):
                admitted.append(s)
                self._admitted_r2.append(r2)
                self._union(*self._edges[self._loop_edge[s]][:2])
                self._tie(s)
            else:
                self._loop_state[s] = DEFERRED
        return admitted

    # ---------------------------------------------------------------------------------------------- solving
    def update(self, extra_steps: int = 0, final: bool = False) -> None:
        """Hand buffered nodes and factors to iSAM2 (one update; loops gated first), then `extra_steps` empty
        updates (each relinearises where needed). `final` also gates loops still waiting for the gate's warm-up."""
        if not (self._pending_nodes or self._pending_factors or self._pending_loops or extra_steps
                or (final and self._held)):
            return
        t0 = time.perf_counter()
        values = gtsam.Values()
        for k in self._pending_nodes:
            values.insert(k, self._current(k))
        admitted = self._gate(self._pending_loops, final)
        graph = gtsam.NonlinearFactorGraph()
        for f in self._pending_factors:
            graph.add(f)
        for s in admitted:
            graph.add(self._robust(self._loop_factor[s]))
            self._loop_robust[s] = True
        try:
            res = self._isam.update(graph, values)
        except RuntimeError as exc:
            if "ndeterminate" not in str(exc) or self._factorization == "qr":
                raise
            # Cholesky gives up on near-singular information (seen on CSAIL, manhattan): rebuild with QR
            self._rebuild("qr")
            res = self._isam.update(graph, values)
        for _ in range(extra_steps):
            self._isam.update()
        self.updates += 1 + extra_steps
        idx = list(res.getNewFactorsIndices())[len(self._pending_factors):]
        for s, fi in zip(admitted, idx):
            self._loop_slot[s] = int(fi)
            self._loop_state[s] = ADMITTED
        self._trusted.extend(self._pending_factors)
        for k in self._pending_nodes:
            self._in_isam[k] = True
        self._pending_nodes, self._pending_factors, self._pending_loops = [], [], []
        self._estimate = None
        self.seconds += time.perf_counter() - t0

    def _rebuild(self, factorization: str) -> None:
        """A fresh iSAM2 with another factorization, holding every node and factor handed over so far."""
        n = sum(self._in_isam)
        try:            # the failed update may have left new variables behind: take the first n keys only
            v = self._isam.calculateEstimate()
            est = np.array([from_pose(self.dim, v.atPose2(k) if self.dim == 2 else v.atPose3(k)) for k in range(n)])
        except RuntimeError:
            est = np.array([self._guess[k] for k in range(n)])
        self._factorization = factorization
        self._isam = gtsam.ISAM2(_isam_params(self.params, factorization))
        slots = [s for s in range(len(self._loop_slot)) if self._loop_slot[s] >= 0]
        graph = graph_of(self._trusted + [self._robust(self._loop_factor[s]) if self._loop_robust[s]
                                          else self._loop_factor[s] for s in slots])
        res = self._isam.update(graph, values_from_array(self.dim, est))
        for s, fi in zip(slots, list(res.getNewFactorsIndices())[len(self._trusted):]):
            self._loop_slot[s] = int(fi)
        self._estimate = None
        self.notes.append(f"iSAM2 rebuilt with {factorization} factorization after an indeterminate-system error")

    def adopt(self, inlier: np.ndarray, poses: np.ndarray) -> None:
        """Take a decision made elsewhere (the batch rejector): iSAM2 is rebuilt holding the trusted factors and
        exactly the `inlier` loops (plain Gaussian factors: decided, no kernel), linearised at `poses` (one row per
        node handed over, in order). Later arrivals continue from there: gated against the decided map, drift
        restarting at the decided loops.

        A rebuild rather than removals and insertions: the decision may move the map by metres (the loops the gate
        deferred under drift), more than iSAM2's relinearisation recovers in a few steps."""
        self.update(final=True)
        inlier = np.asarray(inlier, bool)
        n = sum(self._in_isam)
        if len(inlier) != self.num_loops or len(poses) < n:
            raise ValueError(f"adopt: {len(inlier)} labels for {self.num_loops} loops, {len(poses)} poses for {n}")
        t0 = time.perf_counter()
        kept = np.flatnonzero(inlier).tolist()
        graph = graph_of(self._trusted + [self._loop_factor[s] for s in kept])
        values = values_from_array(self.dim, np.asarray(poses, float)[:n])
        self._isam = gtsam.ISAM2(_isam_params(self.params, self._factorization))
        try:
            res = self._isam.update(graph, values)
        except RuntimeError as exc:
            if "ndeterminate" not in str(exc) or self._factorization == "qr":
                raise
            self._factorization = "qr"         # as in update(): Cholesky gives up on near-singular information
            self._isam = gtsam.ISAM2(_isam_params(self.params, self._factorization))
            res = self._isam.update(graph, values)
        self._loop_slot = [-1] * self.num_loops
        for s, fi in zip(kept, list(res.getNewFactorsIndices())[len(self._trusted):]):
            self._loop_slot[s] = int(fi)
        self._loop_robust = [False] * self.num_loops
        self._loop_state = [ADMITTED if ok else REJECTED for ok in inlier.tolist()]
        for s in kept:
            self._union(*self._edges[self._loop_edge[s]][:2])
            self._tie(s)
        self._estimate = None
        self.updates += 1
        self.seconds += time.perf_counter() - t0

    def estimate(self) -> tuple[np.ndarray, np.ndarray]:
        """(node ids, poses) of everything handed to iSAM2 so far; computed once per update, then cached."""
        n = sum(self._in_isam)
        if n == 0:
            return np.zeros(0, np.int64), np.zeros((0, POSE_WIDTH[self.dim]))
        if self._estimate is None:
            self._estimate = self._isam.calculateEstimate()
        return id_array(self._ids[:n]), array_from_values(self.dim, self._estimate, n)

    def pose(self, node_id: int) -> np.ndarray:
        """Current pose of one node (a node not yet handed to iSAM2 returns its guess)."""
        k = self._key.get(int(node_id))
        if k is None:
            raise KeyError(f"unknown node id {int(node_id)}")
        return from_pose(self.dim, self._current(k))

    def marginal_covariance(self, node_id: int) -> np.ndarray:
        """Marginal covariance of a node in gtsam's tangent order (x, y, theta in 2D; rotation first in 3D)."""
        self.update()
        return np.asarray(self._isam.marginalCovariance(self._key[int(node_id)]))

    @property
    def num_nodes(self) -> int:
        return len(self._ids)

    @property
    def num_loops(self) -> int:
        return len(self._loop_edge)

    def loop_inliers(self) -> np.ndarray:
        """Current labels: True for loops in the graph (admitted or accepted), False for deferred / rejected."""
        return np.asarray([s == ADMITTED for s in self._loop_state], bool)

    def loop_states(self) -> np.ndarray:
        """0 pending, 1 in the graph, 2 deferred by the gate, 3 rejected by classification."""
        return np.asarray(self._loop_state, np.int8)

    def to_data(self) -> PoseGraphData:
        """Everything added so far as a `PoseGraphData` (node poses: current estimate, else the guesses)."""
        w, d = POSE_WIDTH[self.dim], TANGENT_DIM[self.dim]
        n = len(self._ids)
        poses = np.full((n, w), np.nan)
        for k, g in enumerate(self._guess):
            if g is not None:
                poses[k] = g
        ids_est, est = self.estimate()
        poses[:len(ids_est)] = est
        ids = id_array(self._ids)
        if not self._edges:
            return PoseGraphData(self.dim, ids, poses, [], [], np.zeros((0, w)), np.zeros((0, d, d)), [], [])
        ki, kj, z, info, lp, p = zip(*self._edges)
        lp = np.array(lp)
        return PoseGraphData(self.dim, ids, poses, ids[list(ki)], ids[list(kj)], np.array(z), np.array(info), lp,
                             np.where(lp, np.array(p), 1.0))

    def classify_loops(self) -> np.ndarray:
        """Label every loop with the batch robust solve warm-started from the current estimate (GNC on the admitted
        loops, then every loop re-tested, deferred ones included), and make iSAM2 use exactly the inliers.

        Cost: one batch solve of the whole graph, so call it at the end or every few hundred nodes, not per frame.
        Returns the labels (one per loop, True = inlier).
        """
        self.update(final=True)
        if not self._loop_edge or self.params.robust.method == RobustMode.NONE:
            return self.loop_inliers()
        t0 = time.perf_counter()
        cand = self.loop_inliers()
        res = solve(self.to_data(), self.params.replace(solver={"method": Solver.LM, "init": InitMethod.GIVEN}),
                    candidates=cand)
        remove, add = [], []
        for s, ok in enumerate(res.loop_inlier.tolist()):
            in_isam = self._loop_slot[s] >= 0
            if in_isam and (not ok or self._loop_robust[s]):
                remove.append(self._loop_slot[s])     # rejected, or accepted and to be trusted (kernel off)
                self._loop_slot[s] = -1
            if ok and (not in_isam or self._loop_robust[s]):
                add.append(s)
            prev = self._loop_state[s]
            self._loop_state[s] = ADMITTED if ok else (DEFERRED if prev == DEFERRED else REJECTED)
        if remove or add:
            # classified inliers enter as plain Gaussian factors: the estimate converges to least squares over the
            # inliers instead of the kernel's compromise (the kernel only protects loops not yet classified)
            for s in add:
                self._loop_robust[s] = False
            graph = graph_of([self._loop_factor[s] for s in add])
            r = self._isam.update(graph, gtsam.Values(), remove)
            self.updates += 1
            for s, fi in zip(add, list(r.getNewFactorsIndices())):
                self._loop_slot[s] = int(fi)
            self._estimate = None
        self.seconds += time.perf_counter() - t0
        return self.loop_inliers()

    def result(self, classify: bool = True) -> GraphResult:
        """Flush, classify the loops (robust modes), run `isam2_final_steps` more updates, and report."""
        t0 = time.perf_counter()
        self.update(final=True)
        if classify:
            self.classify_loops()
        if self.params.incremental.final_steps:
            t1 = time.perf_counter()
            for _ in range(self.params.incremental.final_steps):
                self._isam.update(force_relinearize=True)
            self.seconds += time.perf_counter() - t1
            self.updates += self.params.incremental.final_steps
            self._estimate = None
        data = self.to_data()
        built = build(data, self.params.replace(solver=Solver.LM))
        values = values_from_array(self.dim, data.poses)
        r2 = squared_residuals(built.loops, values)
        c2 = np.asarray(self._loop_c2)
        inlier = self.loop_inliers()
        if self.params.robust.method == RobustMode.NONE:
            inlier = r2 <= c2
        kept = built.graph(inlier)
        guesses = np.array([g if g is not None else np.full(POSE_WIDTH[self.dim], np.nan) for g in self._guess])
        init_cost = float(kept.error(values_from_array(self.dim, guesses))) if np.isfinite(guesses).all() else np.nan
        if self.params.robust.method in (RobustMode.GNC, RobustMode.NONE):
            weights = inlier.astype(float) if self.params.robust.method == RobustMode.GNC else np.ones(len(inlier))
        else:
            weights = mestimator_weights(r2, self.params.robust.method, self.params)
        report_seconds = time.perf_counter() - t0
        return GraphResult(self.dim, data.node_ids, data.poses, built.loop_idx, inlier, weights, r2, init_cost,
                           float(kept.error(values)), self.updates, self.seconds, 0.0, Solver.ISAM2.value,
                           self.params.robust.method.value, "odometry", 0,
                           [f"iSAM2: {self.updates} updates, {self.params.incremental.batch_nodes} nodes per update, "
                            f"{self._factorization}; report {report_seconds:.3f} s"] + self.notes)


def replay(data: PoseGraphData, params: GraphParams) -> tuple[IncrementalPoseGraph, np.ndarray]:
    """Feed a whole graph to an IncrementalPoseGraph in node order; returns it and the edge arrival order.

    Node k arrives with the edges linking it to nodes 0..k (in data order); its guess is composed from odometry
    (the file's vertex guess is used only when no odometry edge reaches it).
    """
    inc = IncrementalPoseGraph(data.dim, params)
    a, b = data.edge_index_pairs()
    arrival = np.maximum(a, b)
    order = np.argsort(arrival, kind="stable")
    starts = np.searchsorted(arrival[order], np.arange(data.num_nodes + 1))
    ids = data.node_ids.tolist()
    guesses = data.poses
    loops = data.is_loop.tolist()
    prob = data.probability.tolist()
    for k in range(data.num_nodes):
        inc.add_node(ids[k], guesses[k] if k == 0 and np.isfinite(guesses[k]).all() else None)
        for e in order[starts[k]:starts[k + 1]].tolist():
            i, j = ids[a[e]], ids[b[e]]
            if loops[e]:
                inc.add_loop(i, j, data.measurements[e], information=data.information[e],
                             probability=None if np.isnan(prob[e]) else prob[e])
            else:
                inc.add_odometry(i, j, data.measurements[e], information=data.information[e])
        if not inc.placed(ids[k]):
            if not np.isfinite(guesses[k]).all():
                raise ValueError(f"node {ids[k]} is not linked to earlier nodes by odometry and has no guess")
            inc.place(ids[k], guesses[k])
    inc.update(final=True)
    return inc, order


def _loop_order(data: PoseGraphData, order: np.ndarray) -> np.ndarray:
    """For each loop in arrival order, its rank among the data's loops (data order)."""
    arrival_loops = order[data.is_loop[order]]
    rank_in_data = np.empty(data.num_edges, np.int64)
    rank_in_data[np.flatnonzero(data.is_loop)] = np.arange(data.num_loops)
    return rank_in_data[arrival_loops]


def gate_pass(data: PoseGraphData, params: GraphParams) -> tuple[np.ndarray, np.ndarray]:
    """Replay the graph through the gated iSAM2 pass: (estimate (N, w) in node order, admitted flag per loop in
    data order)."""
    inc, order = replay(data, params.replace(robust={"gate_loops": True},
                                               incremental={"batch_nodes": params.incremental.gate_batch_nodes}))
    _, est = inc.estimate()
    admitted = np.zeros(data.num_loops, bool)
    admitted[_loop_order(data, order)] = inc.loop_inliers()
    return est, admitted


def full_pass(data: PoseGraphData, params: GraphParams) -> GraphResult:
    """The whole graph through iSAM2 as an online system would see it; loops classified at the end (robust modes).
    Loop results are reported in data order."""
    t0 = time.perf_counter()
    inc, order = replay(data, params)
    res = inc.result(classify=params.robust.method != RobustMode.NONE)
    res.seconds = time.perf_counter() - t0
    perm = np.empty(data.num_loops, np.int64)
    perm[_loop_order(data, order)] = np.arange(data.num_loops)    # data loop r -> arrival slot perm[r]
    res.loop_edges = np.flatnonzero(data.is_loop)
    res.loop_inlier = res.loop_inlier[perm]
    res.loop_weight = res.loop_weight[perm]
    res.loop_residual = res.loop_residual[perm]
    return res
