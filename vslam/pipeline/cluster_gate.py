"""The pipeline's motion gate: anchored on the closed map, and asking a cluster before a first, unanchored loop on a
floor with look-alikes.

Once loops are accepted, a candidate is judged against the path through an accepted loop near both keyframes
(`AnchoredMotion`), so a candidate a tile period away from where the closed map puts the camera fails. The first
loop of a region has no such anchor: it is judged against the VO chain alone, whose uncertainty after a lap can
exceed half a tile period, where an aliased candidate and the true one are equally plausible. On a floor known to
repeat (the run has already seen a look-alike: a verified candidate with a clean rigid fit that the motion put
elsewhere), such an unanchored loop is accepted only when a candidate of one of the previous `cluster_queries`
query keyframes, itself consistent with the VO, agrees with it through a short path (its match -> VO -> this
candidate, its query -> VO -> this query): two queries independently putting the camera at the same place. An
isolated alias is then refused. A consistent shift of a whole cluster, when the VO error between the laps exceeds
half a period, is undecidable from the VO and stays so; the anchored gate then at least keeps later loops
consistent with the cluster, and the back end judges the cluster against the rest of the map.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from loops.recognition import Verification
from odometry.shared.poses import compose, inverse, wrap_angle
from vslam.pipeline.anchored_motion import Anchor, AnchoredMotion, agree
from vslam.pipeline.loop_pose import LoopPose
from vslam.pipeline.motion_gate import GateResult, MotionGate, MotionGateParams


class ClusterGate(MotionGate):
    """`MotionGate` over an `AnchoredMotion`, with the cluster rule of the module docstring."""

    def __init__(self, fit: Callable[[Verification], LoopPose | None], relative: AnchoredMotion,
                 params: MotionGateParams | None = None):
        super().__init__(fit, relative, params)
        self.anchored = relative
        self.lookalikes = 0                       # verified candidates with a rigid fit that the motion refused
        self.tentative: list[Anchor] = []         # unanchored candidates consistent with the VO, newest last
        self.queries: list[int] = []              # query keys seen, in order
        self.alias_distance = np.inf              # nearest separation of two places one query matched (m)

    def __call__(self, candidate: int, query: int, v: Verification) -> bool:
        if not self.queries or self.queries[-1] != query:
            self.queries.append(int(query))
        res = self.check(candidate, query, v)
        if not res.consistent:
            if res.fit is not None:
                self.lookalikes += 1
            self.results[(int(candidate), int(query))] = res
            return False
        if self.params.refuse_ambiguous and np.isfinite(self.alias_distance):
            _, odo_cov = self.relative(candidate, query)
            s = np.asarray(odo_cov)[:2, :2] + np.asarray(res.fit.covariance)[:2, :2]
            reach = float(np.sqrt(self.params.chi2 * np.linalg.eigvalsh(s).max()))
            if reach >= 0.5 * self.alias_distance:   # the gate would pass the nearest alias as well
                res = GateResult(False, res.mahalanobis2, res.fit)
                self.results[(int(candidate), int(query))] = res
                return False
        if self.params.cluster_queries > 0 and self.lookalikes > 0 \
                and self.anchored.used.get((int(candidate), int(query))) is None:
            me = Anchor(int(candidate), int(query), res.fit.delta, res.fit.covariance)
            ok = self._supported(me)
            self.tentative.append(me)
            res = GateResult(ok, res.mahalanobis2, res.fit)
        self.results[(int(candidate), int(query))] = res
        return res.consistent

    def _supported(self, me: Anchor) -> bool:
        """Does a tentative loop of one of the previous `cluster_queries` query keyframes agree with `me`?"""
        recent = set(self.queries[-1 - self.params.cluster_queries:-1])
        a = self.anchored
        return any(agree(a.chain, me, t, self.params.chi2, a.unscaled, a.scale_fraction) for t in self.tentative
                   if t.query in recent)

    def resolve(self, query: int, candidates: list[int]) -> list[int]:
        """As `MotionGate.resolve`, and note how far apart two places are that the query matched while they
        cannot both be right (the floor's alias distance, e.g. its tile period)."""
        for i, a in enumerate(candidates):
            for b in candidates[i + 1:]:
                lo, hi = min(a, b), max(a, b)
                fa, fb = self.results[(lo, query)].fit, self.results[(hi, query)].fit
                odo, cov = self.relative(lo, hi)
                r = compose(fa.delta, inverse(fb.delta)) - odo
                r[2] = wrap_angle(r[2])
                s = cov + fa.covariance + fb.covariance + np.eye(3) * 1e-12
                if float(r @ np.linalg.solve(s, r)) > self.params.chi2:
                    self.alias_distance = min(self.alias_distance, float(np.hypot(r[0], r[1])))
        return super().resolve(query, candidates)
