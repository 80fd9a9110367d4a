"""Floor footprints of images at planar poses and their overlap J (seed 001, eq. 3-4).

J(a, b) = area(A ∩ B) / area(A ∪ B) where A, B are the floor regions seen by the images at poses a, b.
loop(a, b) = 1 when J >= r (r = 0.33 in the paper).
"""
from __future__ import annotations

import numpy as np
import shapely

from odometry.shared.camera import CameraModel
from odometry.shared.poses import rot2

DEFAULT_OVERLAP_THRESHOLD = 0.33


def footprint_polygon(camera: CameraModel, pose: np.ndarray, samples_per_side: int = 8) -> np.ndarray:
    """World-frame footprint polygon (M, 2) of the image taken at planar pose (x, y, theta)."""
    pose = np.asarray(pose, dtype=float)
    return camera.footprint(samples_per_side) @ rot2(pose[2]).T + pose[:2]


def footprint_polygons(camera: CameraModel, poses: np.ndarray, samples_per_side: int = 8) -> np.ndarray:
    """World-frame footprints (N, M, 2) for poses (N, 3), vectorised."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    local = camera.footprint(samples_per_side)
    return np.einsum("mj,nij->nmi", local, rot2(p[:, 2])) + p[:, None, :2]


def footprint_overlap(camera: CameraModel, pose_a: np.ndarray, pose_b: np.ndarray) -> float:
    """J for one pair of poses."""
    return float(overlap_pairs(camera, np.asarray(pose_a)[None], np.asarray(pose_b)[None])[0])


def overlap_pairs(camera: CameraModel, poses_a: np.ndarray, poses_b: np.ndarray,
                  samples_per_side: int = 8) -> np.ndarray:
    """J for pairs (poses_a[i], poses_b[i]), shape (N,). Pairs farther apart than the footprint diameter
    skip the polygon clipping (J = 0 exactly)."""
    pa = np.asarray(poses_a, dtype=float).reshape(-1, 3)
    pb = np.asarray(poses_b, dtype=float).reshape(-1, 3)
    if len(pa) != len(pb):
        raise ValueError(f"{len(pa)} poses against {len(pb)}")
    out = np.zeros(len(pa))
    local = camera.footprint(samples_per_side)
    # both footprints lie within radius rmax of their pose (the polygon is rigidly attached to the robot)
    rmax = float(np.max(np.linalg.norm(local, axis=1)))
    near = np.linalg.norm(pa[:, :2] - pb[:, :2], axis=1) < 2 * rmax
    if not np.any(near):
        return out
    ga = shapely.polygons(footprint_polygons(camera, pa[near], samples_per_side))
    gb = shapely.polygons(footprint_polygons(camera, pb[near], samples_per_side))
    inter = shapely.area(shapely.intersection(ga, gb))
    union = shapely.area(ga) + shapely.area(gb) - inter
    out[near] = np.where(union > 0, inter / np.maximum(union, 1e-300), 0.0)
    return out


def overlap_matrix(camera: CameraModel, poses: np.ndarray, min_separation: int = 0) -> np.ndarray:
    """Dense J matrix (N, N) for all pairs of poses (symmetric, diagonal 1). Pairs whose frame indices differ by
    less than `min_separation` are left at 0 except the diagonal. Only near pairs are clipped, found with a KD-tree,
    so it stays fast for thousands of poses."""
    from scipy.spatial import cKDTree

    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    n = len(p)
    J = np.eye(n)
    if n < 2:
        return J
    rmax = float(np.max(np.linalg.norm(camera.footprint(), axis=1)))
    pairs = cKDTree(p[:, :2]).query_pairs(2 * rmax, output_type="ndarray")
    if min_separation > 0 and len(pairs):
        pairs = pairs[np.abs(pairs[:, 0] - pairs[:, 1]) >= min_separation]
    if len(pairs):
        j = overlap_pairs(camera, p[pairs[:, 0]], p[pairs[:, 1]])
        J[pairs[:, 0], pairs[:, 1]] = j
        J[pairs[:, 1], pairs[:, 0]] = j
    return J


def is_loop(j: np.ndarray | float, r: float = DEFAULT_OVERLAP_THRESHOLD) -> np.ndarray | bool:
    """loop(a, b, r) of seed 001 eq. (4)."""
    return np.asarray(j) >= r
