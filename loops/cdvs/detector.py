"""Loop detection alone over an image stream: encode each keyframe, query the database, then add it.

This is what `vslam loops` runs; it needs no odometry, ground truth or camera height.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterable

import numpy as np

from loops.cdvs.codec import decode, encode
from loops.cdvs.database import Candidate, DatabaseParams, LoopDatabase
from loops.cdvs.params import CdvsParams
from loops.cdvs.trained import TrainedParams, load_trained
from loops.loop_detector import MotionGate
from odometry.shared.camera import CameraModel

LOOPS_CSV_HEADER = ("query_frame", "match_frame", "global_score", "local_score", "probability", "accepted",
                    "motion_consistent")


@dataclass(frozen=True)
class LoopRow:
    query_frame: int
    candidate: Candidate

    def csv(self) -> str:
        c = self.candidate
        p = "" if c.probability is None else f"{c.probability:.4f}"
        m = "" if c.motion_consistent is None else str(int(c.motion_consistent))
        return f"{self.query_frame},{c.frame_id},{c.global_score:.5f},{c.local_score:.4f},{p},{int(c.accepted)},{m}"


@dataclass
class DetectionStats:
    frames: int = 0
    skipped: int = 0             # frames that could not be read
    candidates: int = 0
    accepted: int = 0
    bytes_total: int = 0
    encode_seconds: float = 0.0
    query_seconds: float = 0.0


def detect_loops(frames: Iterable[tuple[int, np.ndarray | None]], mode: int, params: CdvsParams | None = None,
                 db_params: DatabaseParams | None = None, model=None, trained: TrainedParams | None = None,
                 threshold: float | None = None,
                 on_frame: Callable[[int], None] | None = None, stamps: np.ndarray | None = None,
                 poses: np.ndarray | None = None, camera: CameraModel | None = None,
                 gate: MotionGate | None = None) -> tuple[list[LoopRow], DetectionStats]:
    """Run the detector over (frame index, image or None if unreadable) pairs in increasing frame order.
    `stamps` / `poses`: per frame index, time (s) and odometry pose (x, y, theta), for the time and footprint
    exclusion of recent keyframes (with `camera`); `gate`: the motion check of verified candidates."""
    trained = trained or load_trained()
    params = params or CdvsParams.for_mode(mode)
    db = LoopDatabase(mode, params, db_params, model=model, trained=trained, threshold=threshold, camera=camera,
                      gate=gate)
    rows: list[LoopRow] = []
    st = DetectionStats()
    for k, (idx, img) in enumerate(frames):
        if on_frame is not None:
            on_frame(k)
        if img is None:
            st.skipped += 1
            continue
        t0 = time.perf_counter()
        data = encode(img, mode, params, trained)
        d = decode(data)
        t1 = time.perf_counter()
        stamp = None if stamps is None else float(stamps[idx])
        cands = db.query(d, idx, stamp)
        db.add(idx, d, stamp, None if poses is None else poses[idx])
        t2 = time.perf_counter()
        st.frames += 1
        st.bytes_total += len(data)
        st.encode_seconds += t1 - t0
        st.query_seconds += t2 - t1
        for c in cands:
            rows.append(LoopRow(idx, c))
            st.candidates += 1
            st.accepted += int(c.accepted)
    return rows, st
