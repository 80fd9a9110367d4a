"""Loop database: index descriptors as keyframes arrive, answer "which earlier keyframes match this one".

The cdvs face of the shared loop detector (loops.loop_detector): retrieval by the global descriptor
(CdvsRecognizer), verification by local matching + geometric check on the shortlist only (CdvsVerifier), and the
shared acceptance policy (recent-keyframe exclusion, shortlist, confirmation by consecutive query keyframes),
with results as cdvs Candidates.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from loops.cdvs.codec import Descriptor
from loops.cdvs.match import MatchResult
from loops.cdvs.model import LoopModel
from loops.cdvs.params import CdvsParams
from loops.cdvs.recognizer import CdvsRecognizer, CdvsVerifier
from loops.cdvs.trained import TrainedParams, load_trained
from loops.loop_detector import DatabaseParams, LoopCandidate, LoopDetector, MotionGate
from odometry.shared.camera import CameraModel

__all__ = ["Candidate", "DatabaseParams", "LoopDatabase"]


@dataclass(frozen=True)
class Candidate:
    frame_id: int                  # the stored keyframe's id
    global_score: float
    local_score: float
    n_inliers: int
    match: MatchResult             # inlier pixel pairs: query keypoints in inliers_a, stored in inliers_b
    passes: bool                   # local score >= the acceptance threshold (and overlap >= min_overlap)
    confirmed: bool                # passes and confirmed by the previous query keyframes
    probability: float | None      # P(loop | local score) when the database has a LoopModel
    motion_consistent: bool | None = None   # the motion gate's verdict (None: no gate or not verified)

    @property
    def accepted(self) -> bool:
        return self.passes and self.confirmed

    @classmethod
    def of(cls, c: LoopCandidate) -> "Candidate":
        r: MatchResult = c.verification.detail
        return cls(int(c.key), float(r.global_score), r.local_score, r.n_inliers, r, c.passes, c.confirmed,
                   c.verification.probability, c.motion_consistent)


def resolve_min_overlap(db: DatabaseParams, model: LoopModel | None) -> float:
    """The policy's min_overlap, or the loop model's when not given (0 without a model)."""
    if db.min_overlap is not None:
        return float(db.min_overlap)
    return float(getattr(model, "min_overlap", None) or 0.0)


def cdvs_loop_detector(mode: int, params: CdvsParams | None = None, db_params: DatabaseParams | None = None,
                       model: LoopModel | None = None, trained: TrainedParams | None = None,
                       threshold: float | None = None, camera: CameraModel | None = None,
                       gate: MotionGate | None = None) -> LoopDetector:
    """The shared loop detector over compact descriptors of one mode (`camera`: footprints of keyframes added
    with poses; `gate`: motion check of verified candidates; see loops.loop_detector)."""
    params = params or CdvsParams.for_mode(mode)
    trained = trained or load_trained()
    db = db_params or DatabaseParams()
    return LoopDetector(CdvsRecognizer(mode, params, trained),
                        CdvsVerifier(mode, params, trained, model, threshold),
                        replace(db, min_overlap=resolve_min_overlap(db, model)), camera=camera, gate=gate)


class LoopDatabase:
    """Keyframe database for one descriptor mode."""

    def __init__(self, mode: int, params: CdvsParams | None = None, db_params: DatabaseParams | None = None,
                 model: LoopModel | None = None, trained: TrainedParams | None = None,
                 threshold: float | None = None, camera: CameraModel | None = None, gate: MotionGate | None = None):
        self.mode = mode
        self.params = params or CdvsParams.for_mode(mode)
        self.db = db_params or DatabaseParams()
        self.trained = trained or load_trained()
        self.model = model
        self.detector = cdvs_loop_detector(mode, self.params, self.db, model, self.trained, threshold, camera, gate)
        self.recognizer: CdvsRecognizer = self.detector.recognizer
        self.threshold = self.detector.verifier.threshold
        self.min_overlap = self.detector.min_overlap

    def __len__(self) -> int:
        return len(self.detector)

    def add(self, frame_id: int, descriptor: Descriptor, stamp: float | None = None,
            pose: np.ndarray | None = None) -> None:
        """Store a keyframe's descriptor (frame ids must increase), with its time (s) and odometry pose if known."""
        self.recognizer.check(descriptor)
        self.detector.add(frame_id, descriptor, stamp, pose)

    def global_scores(self, descriptor: Descriptor, n: int | None = None) -> np.ndarray:
        """Global scores of `descriptor` against the first `n` stored keyframes (default all)."""
        return self.recognizer.global_scores(descriptor, n)

    def query(self, descriptor: Descriptor, frame_id: int | None = None, stamp: float | None = None) -> list[Candidate]:
        """Verified candidates for `descriptor`, best local score first. Only keyframes of another visit are
        considered (loops.loop_detector: count, time and footprint exclusion; smaller ids than `frame_id`)."""
        return [Candidate.of(c) for c in self.detector.query(descriptor, frame_id, stamp)]
