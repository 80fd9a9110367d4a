"""Loop-closure quality against footprint-overlap ground truth (seed 001 eq. 3-4): loop(a, b) = J(a, b) >= r.
The counting is loops.curves.confusion; what is specific here is the ground truth from poses."""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loops.curves import confusion
from odometry.shared.camera import CameraModel
from odometry.shared.footprint import DEFAULT_OVERLAP_THRESHOLD, overlap_matrix, overlap_pairs
from vslam.errors import VslamError

LOOPS_HEADER = ("query_frame", "match_frame", "global_score", "local_score", "probability", "accepted")
RUN_LOOPS_HEADER = LOOPS_HEADER + ("inlier",)


@dataclass(frozen=True)
class LoopTable:
    query: np.ndarray
    match: np.ndarray
    global_score: np.ndarray
    local_score: np.ndarray
    probability: np.ndarray
    accepted: np.ndarray          # bool
    inlier: np.ndarray | None     # bool where known (after optimisation), else None

    def __len__(self) -> int:
        return len(self.query)


def read_loops_csv(path: str | Path) -> LoopTable:
    """Read loops.csv (the `vslam loops` columns, plus `inlier` when written by `vslam run`)."""
    path = Path(path)
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        cols = reader.fieldnames or []
        missing = [c for c in LOOPS_HEADER if c not in cols]
        if missing:
            raise VslamError(f"{path}:1: field '{missing[0]}': missing column (expected {','.join(LOOPS_HEADER)})")
        rows = list(reader)
    def col(name, kind=float):
        out = []
        for i, r in enumerate(rows, 2):
            v = r[name]
            try:
                out.append(kind(v) if v != "" else (np.nan if kind is float else -1))
            except ValueError:
                raise VslamError(f"{path}:{i}: field '{name}': not a number: {v!r}") from None
        return np.asarray(out)
    inl = None
    if "inlier" in cols:
        inl = np.array([r["inlier"] == "1" for r in rows], dtype=bool)
    return LoopTable(query=col("query_frame", int), match=col("match_frame", int), global_score=col("global_score"),
                     local_score=col("local_score"), probability=col("probability"),
                     accepted=col("accepted", int) == 1, inlier=inl)


def loop_precision_recall(camera: CameraModel, gt_poses: np.ndarray, loops: LoopTable, queried: np.ndarray | None = None,
                          r: float = DEFAULT_OVERLAP_THRESHOLD, min_separation: int = 1,
                          use_inliers: bool = False, stamps: np.ndarray | None = None, min_seconds: float = 0.0,
                          after_leaving: bool = False) -> dict:
    """Precision of the reported loops and recall over the queries that had a true loop.

    gt_poses: (N, 3) planar ground truth per frame. queried: frame indices that were queried for loops (keyframes);
    a query counts as a positive when some queried frame at least `min_separation` queries earlier has J >= r
    (the detector's own exclusion of recent keyframes, so neighbours in time are not counted as missed loops).
    The detector's other exclusions, when it used them: `stamps` (per frame) and `min_seconds`, an earlier frame
    counts only when it is that much older; `after_leaving`, only once a later queried frame's footprint no longer
    overlaps it (the camera left the place: a revisit, not the same visit).
    use_inliers: judge the loops kept by the back end (accepted and inlier) instead of all accepted ones.
    """
    keep = loops.accepted & (loops.inlier if (use_inliers and loops.inlier is not None) else True)
    q, m = loops.query[keep], loops.match[keep]
    valid = ~np.isnan(gt_poses[q, 0]) & ~np.isnan(gt_poses[m, 0]) if len(q) else np.zeros(0, bool)
    J = overlap_pairs(camera, gt_poses[q[valid]], gt_poses[m[valid]]) if np.any(valid) else np.zeros(0)
    reported = confusion(np.ones(len(J), bool), J >= r)      # every reported loop counts as accepted
    out = {"reported": int(len(q)), "true_positives": reported.true_positives,
           "false_positives": reported.false_positives, "precision": reported.precision}
    if queried is not None:
        queried = np.asarray(sorted(set(int(i) for i in queried)))
        P = gt_poses[queried]
        ok = ~np.isnan(P[:, 0])
        Jm = np.zeros((len(queried), len(queried)))
        if ok.sum() > 1:
            Jm[np.ix_(ok, ok)] = overlap_matrix(camera, P[ok])
        rank = np.arange(len(queried))
        earlier = (rank[:, None] - rank[None, :]) >= max(1, min_separation)     # [query, earlier frame]
        if stamps is not None and min_seconds > 0:
            ts = np.asarray(stamps, dtype=float)[queried]
            earlier &= (ts[:, None] - ts[None, :]) >= min_seconds
        if after_leaving:
            apart = np.triu((Jm <= 0) & ok[:, None] & ok[None, :], 1)     # [frame, later frame]: no overlap
            first = np.where(apart.any(axis=1), np.argmax(apart, axis=1), len(queried))
            earlier &= rank[:, None] >= first[None, :]
        positive = np.any((Jm >= r) & earlier, axis=1)
        hit_queries = set(int(a) for a, jj in zip(q[valid], J) if jj >= r)
        found = np.array([int(f) in hit_queries for f in queried])
        recalled = confusion(found, positive)
        out.update({"queries": int(len(queried)), "positive_queries": recalled.positives,
                    "recalled_queries": recalled.true_positives, "recall": recalled.recall})
    return out
