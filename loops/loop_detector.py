"""Loop detection over a keyframe stream with any recogniser: the one acceptance policy of the toolkit.

For each new keyframe: retrieve a shortlist among the earlier keyframes that belong to another visit of the place,
verify each shortlisted candidate geometrically, optionally check it against the motion (`gate`), and accept a
verified candidate once consecutive query keyframes agree on the place (DLoopDetector / ORB-SLAM style).

"Another visit" is decided by time and footprint, not by a count of keyframes alone (a count means seconds at
30 fps and minutes at 0.1 Hz): a stored keyframe is a candidate only when it was taken at least `exclude_seconds`
before the query and, when keyframes come with poses (odometry) and a camera, once the camera has left its floor
footprint (a later keyframe's footprint does not overlap it). Until then a match is the same visit seen again,
whatever the frame rate, speed or turn. The recogniser and verifier come from `loops.recognition`; which
keyframes are candidates and when a loop counts is decided here only.
"""
from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from loops.recognition import Recognizer, Verification, Verifier
from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, setting
from odometry.shared.footprint import overlap_pairs

# gate(candidate key, query key, verification) -> consistent with the motion between the two keyframes. A gate may
# also define resolve(query key, candidate keys that passed) -> the keys it keeps: the candidates of one query that
# agree with each other (a query matching two places that cannot both be right is ambiguous, e.g. a periodic floor)
MotionGate = Callable[[int, int, Verification], bool]


@dataclass(frozen=True)
class DatabaseParams(Config):
    """The acceptance policy (config section `loops.database`)."""

    shortlist: int = setting(5, range="[1, inf)", doc="candidates (best retrieval scores) verified geometrically")
    exclude_recent: int = setting(20, range="[0, inf)",
                                  doc="the most recently added keyframes are never candidates")
    exclude_seconds: float = setting(0.0, range="[0, inf)", unit="s",
                                     doc="keyframes taken less than this long before the query are never candidates "
                                         "(needs time stamps)")
    exclude_unleft: bool = setting(True, doc="with poses and a camera: a keyframe becomes a candidate only once a "
                                             "later keyframe's floor footprint no longer overlaps it (the camera "
                                             "left the place; a revisit, not the same visit)")
    min_global: float = setting(-1.0, doc="candidates below this retrieval score are not verified")
    confirmations: int = setting(1, range="[1, inf)",
                                 doc="consecutive query keyframes that must agree before a loop is accepted")
    confirm_window: int = setting(5, range="[0, inf)",
                                  doc='"agree": a verified match within this many stored keyframes of the last one')
    gated_min_probability: float | None = setting(None, range="[0, 1]",
                                                  doc="with a motion gate: a verified candidate below the verifier's "
                                                      "threshold (P(loop|score) = 1) still passes when its "
                                                      "P(loop|score) is at least this, its implied overlap at least "
                                                      "gated_min_overlap and the gate finds it consistent (None: off)")
    gated_min_overlap: float = setting(0.33, range="[0, 1]",
                                       doc="implied image overlap such a gated candidate needs (0.33: the overlap "
                                           "that defines a loop in the loop model)")
    min_overlap: float | None = setting(None, range="[0, 1]")   # accept only if the verified transform implies at
    #                                     least this image overlap; None: the loop model's min_overlap (0 without a model)


@dataclass(frozen=True)
class LoopCandidate:
    """A verified candidate of one query keyframe."""

    key: int                       # the stored keyframe's key (frame id)
    retrieval_score: float         # its score in the recogniser's ranking
    verification: Verification
    passes: bool                   # verified, its overlap >= min_overlap, and consistent with the motion (gate)
    confirmed: bool                # passes and confirmed by the previous query keyframes
    motion_consistent: bool | None = None   # the gate's verdict on a verified candidate (None: no gate / not run)

    @property
    def accepted(self) -> bool:
        return self.passes and self.confirmed

    @property
    def score(self) -> float:
        """The verification score (what candidates are sorted by)."""
        return self.verification.score

    @property
    def global_score(self) -> float:
        """Appearance similarity: the verifier's full-precision value when it has one, else the retrieval score."""
        v = self.verification.similarity
        return self.retrieval_score if v is None else v


class LoopDetector:
    """Query-then-add loop detection over keys that increase (frame ids).

    `policy.min_overlap` None counts as 0 here: a caller with a calibrated model resolves it first.
    `camera`: the downward camera whose floor footprints decide when the camera left a keyframe's place (keyframes
    added with a pose); `gate`: a motion-consistency check of verified candidates (e.g. against odometry)."""

    def __init__(self, recognizer: Recognizer, verifier: Verifier, policy: DatabaseParams | None = None,
                 camera: CameraModel | None = None, gate: MotionGate | None = None):
        self.recognizer = recognizer
        self.verifier = verifier
        self.policy = policy or DatabaseParams()
        self.min_overlap = float(self.policy.min_overlap or 0.0)
        self.camera = camera
        self.gate = gate
        self._keys: list[int] = []
        self._index: dict[int, int] = {}
        self._observations: list[Any] = []
        self._stamps: list[float] = []          # NaN: unknown
        self._poses: list[np.ndarray | None] = []
        self._left: list[bool] = []             # the camera has left this keyframe's footprint
        self._pending: list[int] = []           # indices not left yet (their footprint still overlaps the latest)
        self.lookalikes = 0                     # verified candidates above threshold that the gate refused
        self._history: deque[list[int]] = deque(maxlen=max(1, self.policy.confirmations - 1))

    def __len__(self) -> int:
        return len(self._keys)

    def observation(self, key: int) -> Any:
        return self._observations[self._index[key]]

    def add(self, key: int, observation: Any, stamp: float | None = None, pose: np.ndarray | None = None) -> None:
        """Store a keyframe (keys must increase), with its time stamp (s) and planar pose (x, y, theta) if known."""
        if self._keys and key <= self._keys[-1]:
            raise ValueError(f"frame ids must increase: {key} after {self._keys[-1]}")
        self.recognizer.add(key, observation)
        tracked = pose is not None and self.camera is not None and self.policy.exclude_unleft
        if tracked:
            self._leave(np.asarray(pose, float))
        self._index[key] = len(self._keys)
        self._keys.append(key)
        self._observations.append(observation)
        self._stamps.append(float("nan") if stamp is None else float(stamp))
        self._poses.append(None if pose is None else np.asarray(pose, float))
        self._left.append(not tracked)       # no pose: only time and count decide
        if tracked:
            self._pending.append(len(self._keys) - 1)

    def _leave(self, pose: np.ndarray) -> None:
        """Mark the pending keyframes whose footprint the footprint at `pose` no longer overlaps."""
        if not self._pending:
            return
        stored = np.array([self._poses[i] for i in self._pending])
        j = overlap_pairs(self.camera, stored, np.repeat(pose[None], len(stored), axis=0))
        for i, jj in zip(self._pending, j):
            if jj <= 0.0:
                self._left[i] = True
        self._pending = [i for i in self._pending if not self._left[i]]

    def eligible(self, key: int | None = None, stamp: float | None = None) -> int:
        """How many of the first stored keyframes may be candidates by count and time: all but the
        `exclude_recent` most recent, with `key` only those before it, with `stamp` only those taken at least
        `exclude_seconds` earlier (keyframes without a stamp are not held back by time)."""
        n = len(self._keys) - self.policy.exclude_recent
        if key is not None and n > 0:
            n = min(n, bisect.bisect_left(self._keys, key) - self.policy.exclude_recent)
        if stamp is not None and self.policy.exclude_seconds > 0 and n > 0:
            limit = float(stamp) - self.policy.exclude_seconds
            while n > 0 and self._stamps[n - 1] > limit:   # stamps increase with keys; NaN compares False
                n -= 1
        return n

    def candidates_allowed(self, n: int) -> np.ndarray:
        """Which of the first `n` stored keyframes the camera has left (all, without poses)."""
        return np.asarray(self._left[:max(n, 0)], dtype=bool)

    def query(self, observation: Any, key: int | None = None, stamp: float | None = None) -> list[LoopCandidate]:
        """Verified candidates for `observation`, best verification score first. Call once per query keyframe,
        in order: the confirmation of later loops depends on it. `key` and `stamp` are the query's frame id and
        time (a pose given to the following `add` is not needed here: footprints are compared as keyframes
        arrive)."""
        n = self.eligible(key, stamp)
        verified: list[tuple[int, float, Verification]] = []
        if n > 0:
            allowed = self.candidates_allowed(n)
            held = int((~allowed).sum())
            kept = 0
            # the shortlist is filled from keyframes the camera has left: ask for as many more as are held back
            for r in self.recognizer.query(observation, top=self.policy.shortlist + held, among=n):
                i = self._index[r.key]
                if not allowed[i] or r.score < self.policy.min_global:
                    continue
                verified.append((i, r.score, self.verifier.verify(observation, self._observations[i])))
                kept += 1
                if kept >= self.policy.shortlist:
                    break
        consistent = {i: self._consistent(i, key, v) for i, _, v in verified}
        # look-alikes: candidates above the verifier's threshold that the motion put elsewhere (the floor repeats)
        self.lookalikes += sum(1 for i, _, v in verified if self._passes(v) and consistent[i] is False)
        resolve = getattr(self.gate, "resolve", None)
        if resolve is not None and key is not None:
            gated = [i for i, c in consistent.items() if c]
            kept_keys = set(resolve(key, [self._keys[i] for i in gated])) if gated else set()
            for i in gated:
                consistent[i] = self._keys[i] in kept_keys
        passing = [i for i, _, v in verified if self._passes_gated(v, consistent[i])]
        out = []
        for i, score, v in verified:
            passes = self._passes_gated(v, consistent[i])
            out.append(LoopCandidate(self._keys[i], score, v, passes, passes and self._confirmed(i), consistent[i]))
        self._history.append(passing)
        out.sort(key=lambda c: -c.score)
        return out

    def _consistent(self, index: int, key: int | None, v: Verification) -> bool | None:
        """The motion gate's verdict on a verified candidate (None: no gate, or nothing to check)."""
        if self.gate is None or key is None or not (self._passes(v) or self._below_threshold(v)):
            return None
        return bool(self.gate(self._keys[index], key, v))

    def _passes(self, v: Verification) -> bool:
        return v.accepted and (self.min_overlap <= 0.0 or v.overlap >= self.min_overlap)

    def _below_threshold(self, v: Verification) -> bool:
        """A verified candidate below the verifier's threshold that the motion gate may still admit: likely by its
        score (the threshold is where P(loop|score) reaches 1; below it, a pair is mostly a true partial overlap or a
        look-alike, and the gate tells the look-alike) and overlapping enough to count as a loop. Only while the
        run has seen no look-alike above the threshold: on a floor that repeats (a printed floor) the gate's
        uncertainty after a lap spans several periods, and more candidates only add aliases."""
        p = self.policy.gated_min_probability
        return (self.gate is not None and p is not None and self.lookalikes == 0 and not v.accepted and v.probability is not None
                and v.probability >= p and v.overlap >= max(self.min_overlap, self.policy.gated_min_overlap))

    def _passes_gated(self, v: Verification, consistent: bool | None) -> bool:
        """Passes: above threshold and not refused by the gate, or below it and confirmed by the gate."""
        if self._passes(v):
            return consistent is not False
        return self._below_threshold(v) and consistent is True

    def _confirmed(self, index: int) -> bool:
        need = self.policy.confirmations - 1
        if need <= 0:
            return True
        if len(self._history) < need:
            return False
        w = self.policy.confirm_window
        return all(any(abs(j - index) <= w for j in prev) for prev in list(self._history)[-need:])
