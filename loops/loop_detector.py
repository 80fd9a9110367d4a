"""Loop detection over a keyframe stream with any recogniser: the one acceptance policy of the toolkit.

For each new keyframe: retrieve a shortlist among the keyframes added before the most recent ones, verify each
shortlisted candidate geometrically, and accept a verified candidate once consecutive query keyframes agree on
the place (DLoopDetector / ORB-SLAM style). The recogniser and verifier come from `loops.recognition`; which
keyframes are candidates and when a loop counts is decided here only.
"""
from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass
from typing import Any

from loops.recognition import Recognizer, Verification, Verifier
from odometry.shared.config import Config, setting


@dataclass(frozen=True)
class DatabaseParams(Config):
    """The acceptance policy (config section `loops.database`)."""

    shortlist: int = setting(5, range="[1, inf)", doc="candidates (best retrieval scores) verified geometrically")
    exclude_recent: int = setting(20, range="[0, inf)",
                                  doc="the most recently added keyframes are never candidates")
    min_global: float = setting(-1.0, doc="candidates below this retrieval score are not verified")
    confirmations: int = setting(1, range="[1, inf)",
                                 doc="consecutive query keyframes that must agree before a loop is accepted")
    confirm_window: int = setting(5, range="[0, inf)",
                                  doc='"agree": a verified match within this many stored keyframes of the last one')
    min_overlap: float | None = setting(None, range="[0, 1]")   # accept only if the verified transform implies at
    #                                     least this image overlap; None: the loop model's min_overlap (0 without a model)


@dataclass(frozen=True)
class LoopCandidate:
    """A verified candidate of one query keyframe."""

    key: int                       # the stored keyframe's key (frame id)
    retrieval_score: float         # its score in the recogniser's ranking
    verification: Verification
    passes: bool                   # verified, and its overlap >= min_overlap
    confirmed: bool                # passes and confirmed by the previous query keyframes

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

    `policy.min_overlap` None counts as 0 here: a caller with a calibrated model resolves it first."""

    def __init__(self, recognizer: Recognizer, verifier: Verifier, policy: DatabaseParams | None = None):
        self.recognizer = recognizer
        self.verifier = verifier
        self.policy = policy or DatabaseParams()
        self.min_overlap = float(self.policy.min_overlap or 0.0)
        self._keys: list[int] = []
        self._index: dict[int, int] = {}
        self._observations: list[Any] = []
        self._history: deque[list[int]] = deque(maxlen=max(1, self.policy.confirmations - 1))

    def __len__(self) -> int:
        return len(self._keys)

    def observation(self, key: int) -> Any:
        return self._observations[self._index[key]]

    def add(self, key: int, observation: Any) -> None:
        """Store a keyframe (keys must increase)."""
        if self._keys and key <= self._keys[-1]:
            raise ValueError(f"frame ids must increase: {key} after {self._keys[-1]}")
        self.recognizer.add(key, observation)
        self._index[key] = len(self._keys)
        self._keys.append(key)
        self._observations.append(observation)

    def eligible(self, key: int | None = None) -> int:
        """How many of the first stored keyframes may be candidates: all but the `exclude_recent` most recent,
        and, with `key`, only those before it."""
        n = len(self._keys) - self.policy.exclude_recent
        if key is not None and n > 0:
            n = min(n, bisect.bisect_left(self._keys, key) - self.policy.exclude_recent)
        return n

    def query(self, observation: Any, key: int | None = None) -> list[LoopCandidate]:
        """Verified candidates for `observation`, best verification score first. Call once per query keyframe,
        in order: the confirmation of later loops depends on it."""
        n = self.eligible(key)
        verified: list[tuple[int, float, Verification]] = []
        if n > 0:
            for r in self.recognizer.query(observation, top=self.policy.shortlist, among=n):
                if r.score < self.policy.min_global:
                    continue
                i = self._index[r.key]
                verified.append((i, r.score, self.verifier.verify(observation, self._observations[i])))
        passing = [i for i, _, v in verified if self._passes(v)]
        out = []
        for i, score, v in verified:
            passes = self._passes(v)
            out.append(LoopCandidate(self._keys[i], score, v, passes, passes and self._confirmed(i)))
        self._history.append(passing)
        out.sort(key=lambda c: -c.score)
        return out

    def _passes(self, v: Verification) -> bool:
        return v.accepted and (self.min_overlap <= 0.0 or v.overlap >= self.min_overlap)

    def _confirmed(self, index: int) -> bool:
        need = self.policy.confirmations - 1
        if need <= 0:
            return True
        if len(self._history) < need:
            return False
        w = self.policy.confirm_window
        return all(any(abs(j - index) <= w for j in prev) for prev in list(self._history)[-need:])
