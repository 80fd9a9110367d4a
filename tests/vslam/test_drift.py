"""KITTI-style segment drift (vslam.evaluation.drift), the odometry benchmark's metric."""
import numpy as np

from vslam.evaluation.drift import drift_metrics


def test_drift_metrics():
    t = np.linspace(0, 20, 801)
    gt = np.column_stack([np.cos(t / 3) * 3, np.sin(t / 3) * 3, t / 3 + np.pi / 2])  # a 3 m circle arc
    m = drift_metrics(gt, gt)
    assert m["segment_drift_pct"] < 1e-9 and m["end_drift_pct"] < 1e-9
    line = np.column_stack([np.linspace(0, 12, 601), np.zeros(601), np.zeros(601)])
    m = drift_metrics(line * [1.01, 1, 1], line)  # a 1 % scale error on a straight path
    assert abs(m["segment_drift_pct"] - 1.0) < 1e-6 and abs(m["end_drift_pct"] - 1.0) < 1e-6
    assert m["segment_heading_deg_per_m"] < 1e-9
    bent = gt.copy()
    bent[:, 2] += np.radians(0.1) * np.arange(len(gt)) / (len(gt) - 1)  # heading error growing to 0.1 deg
    assert drift_metrics(bent, gt)["segment_heading_deg_per_m"] > 0
