"""Odometry drift, KITTI-style: the error of relative motions over path segments of fixed lengths as % of the
segment length (averaged over all segment starts), the same for heading in deg/m, and the end-point error as % of
the path length."""
from __future__ import annotations

import numpy as np

from odometry.shared.poses import between, wrap_angle

SEGMENTS = (1.0, 2.0, 5.0, 10.0)


def drift_metrics(est: np.ndarray, gt: np.ndarray, segments=SEGMENTS, step: int = 5) -> dict:
    """Drift of planar poses `est` against `gt` (both (N, 3), same frames; NaN gt rows are skipped): path_m,
    segment_drift_pct, segment_heading_deg_per_m, end_drift_pct, end_heading_deg_per_m. Segment starts every
    `step` frames; segments longer than the path are left out."""
    ok = np.all(np.isfinite(gt), axis=1)
    est, gt = est[ok], gt[ok]
    dist = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(gt[:, :2], axis=0).T))])
    out: dict = {"path_m": float(dist[-1])}
    trans, rot = [], []
    for length in segments:
        if dist[-1] < length:
            continue
        starts = np.arange(0, len(gt), step)
        ends = np.searchsorted(dist, dist[starts] + length)
        keep = ends < len(gt)
        s, e = starts[keep], ends[keep]
        de, dg = between(est[s], est[e]), between(gt[s], gt[e])
        seg_len = dist[e] - dist[s]
        trans.append(np.hypot(*(de[:, :2] - dg[:, :2]).T) / seg_len * 100.0)
        rot.append(np.degrees(np.abs(wrap_angle(de[:, 2] - dg[:, 2]))) / seg_len)
    out["segment_drift_pct"] = float(np.mean(np.concatenate(trans))) if trans else float("nan")
    out["segment_heading_deg_per_m"] = float(np.mean(np.concatenate(rot))) if rot else float("nan")
    g0 = between(gt[0], gt)  # ground truth expressed from its first pose, like the estimate
    e0 = between(est[0], est)
    out["end_drift_pct"] = float(np.hypot(*(e0[-1, :2] - g0[-1, :2])) / max(dist[-1], 1e-9) * 100.0)
    out["end_heading_deg_per_m"] = float(np.degrees(abs(wrap_angle(e0[-1, 2] - g0[-1, 2]))) / max(dist[-1], 1e-9))
    return out
