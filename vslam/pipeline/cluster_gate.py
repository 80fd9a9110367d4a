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
                 params: MotionGateParams | None = None, image_sigma_rms: float = 0.0):
        super().__init__(fit, relative, params, image_sigma_rms)
        self.anchored = relative
        self.lookalikes = 0                       # verified candidates with a rigid fit that the motion refused
        self.tentative: list[Anchor] = []         # unanchored candidates consistent with the VO, newest last
        self.queries: list[int] = []              # query keys seen, in order
        self.alias_distance = np.inf              # nearest separation of two places one query matched (m)
        self.checked: dict[int, list[int]] = {}   # query -> candidates given a floor fit (consistent or not)

    def __call__(self, candidate: int, query: int, v: Verification) -> bool:
        if not self.queries or self.queries[-1] != query:
            self.queries.append(int(query))
        res = self.check(candidate, query, v)
        if res.fit is not None:
            self.checked.setdefault(int(query), []).append(int(candidate))
        if not res.consistent:
            if res.fit is not None:
                self.lookalikes += 1
            self.results[(int(candidate), int(query))] = res
            return False
        if self.params.refuse_ambiguous and not self._decidable(candidate, query, res.fit):
            res = GateResult(False, res.mahalanobis2, res.fit, "alias")
            self.results[(int(candidate), int(query))] = res
            return False
        if self.params.cluster_queries > 0 and self.lookalikes > 0 \
                and self.anchored.used.get((int(candidate), int(query))) is None:
            me = Anchor(int(candidate), int(query), res.fit.delta, res.fit.covariance)
            ok = self._supported(me)
            self.tentative.append(me)
            res = GateResult(ok, res.mahalanobis2, res.fit, "" if ok else "cluster")
        self.results[(int(candidate), int(query))] = res
        return res.consistent

    def _decidable(self, candidate: int, query: int, fit: LoopPose) -> bool:
        """Is the gate narrower than half the floor's alias distance, i.e. would it refuse the nearest alias?"""
        if not np.isfinite(self.alias_distance):
            return True
        _, odo_cov = self.relative(candidate, query)
        s = np.asarray(odo_cov)[:2, :2] + self.fit_covariance(fit)[:2, :2]
        reach = float(np.sqrt(self.params.chi2 * np.linalg.eigvalsh(s).max()))
        return reach < 0.5 * self.alias_distance

    def _supported(self, me: Anchor) -> bool:
        """Does a tentative loop of one of the previous `cluster_queries` query keyframes agree with `me`?"""
        recent = set(self.queries[-1 - self.params.cluster_queries:-1])
        a = self.anchored
        return any(agree(a.chain, me, t, self.params.chi2, a.unscaled, a.scale_fraction) for t in self.tentative
                   if t.query in recent)

    def resolve(self, query: int, candidates: list[int]) -> list[int]:
        """As `MotionGate.resolve`, and note how far apart two places are that the query matched while they
        cannot both be right (the floor's alias distance, e.g. its tile period). Every candidate with a floor fit
        counts, also those the motion refused: two look-alikes of one query, both far from where the odometry
        puts it, still show that the floor repeats at their separation. With `refuse_ambiguous`, the candidates
        are then judged against that distance at once, so the query that reveals the alias cannot pass one."""
        seen = self.checked.get(int(query), [])
        for i, a in enumerate(seen):
            for b in seen[i + 1:]:
                lo, hi = min(a, b), max(a, b)
                fa, fb = self.results[(lo, query)].fit, self.results[(hi, query)].fit
                odo, cov = self.relative(lo, hi)
                r = compose(fa.delta, inverse(fb.delta)) - odo
                r[2] = wrap_angle(r[2])
                s = cov + self.fit_covariance(fa) + self.fit_covariance(fb) + np.eye(3) * 1e-12
                # places apart: the positions alone disagree (two fits differing only in heading are no alias)
                if float(r[:2] @ np.linalg.solve(s[:2, :2], r[:2])) > self.params.chi2:
                    self.alias_distance = min(self.alias_distance, float(np.hypot(r[0], r[1])))
        if self.params.refuse_ambiguous:
            kept = [c for c in candidates if self._decidable(c, query, self.results[(c, query)].fit)]
            for c in candidates:
                if c not in kept:
                    r = self.results[(c, query)]
                    self.results[(c, query)] = GateResult(False, r.mahalanobis2, r.fit, "alias")
            candidates = kept
        return super().resolve(query, candidates)
