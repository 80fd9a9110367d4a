"""Loop ground truth from planar poses: loop(Ia, Ib) = 1 when the floor-footprint overlap J >= r (seed 001 eq. 3-4),
computed with the foundation's footprint geometry."""
from __future__ import annotations

import numpy as np

from odometry.shared.camera import CameraModel
from odometry.shared.footprint import DEFAULT_OVERLAP_THRESHOLD, overlap_pairs


def pair_overlaps(camera: CameraModel, poses: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """J for index pairs (P, 2) into poses (N, 3)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    p = np.asarray(poses, dtype=float)
    if len(pairs) == 0:
        return np.zeros(0)
    return overlap_pairs(camera, p[pairs[:, 0]], p[pairs[:, 1]])


def loop_labels(camera: CameraModel, poses: np.ndarray, pairs: np.ndarray,
                r: float = DEFAULT_OVERLAP_THRESHOLD) -> tuple[np.ndarray, np.ndarray]:
    """(J, loop) for index pairs: loop = J >= r."""
    j = pair_overlaps(camera, poses, pairs)
    return j, j >= r
