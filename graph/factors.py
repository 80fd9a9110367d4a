"""Conversion between `PoseGraphData` arrays and gtsam objects (poses, noise models, factors, values).

Node at position k in `data.node_ids` is gtsam key k. 3D information matrices are permuted from the file order
(translation, rotation) to gtsam's tangent order (rotation, translation), as gtsam's own g2o reader does.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.model import POSE_WIDTH, TANGENT_DIM, PoseGraphData
from odometry.shared.rotations import rotmat_to_quat

_PERM_3D = np.array([3, 4, 5, 0, 1, 2])


def to_pose(dim: int, row: np.ndarray):
    """gtsam.Pose2 from (x, y, theta) or gtsam.Pose3 from (x, y, z, qx, qy, qz, qw)."""
    r = np.asarray(row, dtype=float)
    if dim == 2:
        return gtsam.Pose2(float(r[0]), float(r[1]), float(r[2]))
    return gtsam.Pose3(gtsam.Rot3.Quaternion(float(r[6]), float(r[3]), float(r[4]), float(r[5])), r[:3].copy())


def from_pose(dim: int, pose) -> np.ndarray:
    if dim == 2:
        return np.array([pose.x(), pose.y(), pose.theta()])
    q = pose.rotation().toQuaternion()
    out = np.array([*pose.translation(), q.x(), q.y(), q.z(), q.w()])
    return out * (1.0 if out[6] >= 0 else np.r_[1.0, 1.0, 1.0, -1.0, -1.0, -1.0, -1.0])


def values_from_array(dim: int, poses: np.ndarray) -> gtsam.Values:
    """Values with key k = row k of (N, 3|7) poses."""
    v = gtsam.Values()
    for k, row in enumerate(np.asarray(poses, float)):
        v.insert(k, to_pose(dim, row))
    return v


def array_from_values(dim: int, values: gtsam.Values, n: int) -> np.ndarray:
    """(n, 3|7) poses for keys 0..n-1 (all must exist)."""
    if n == 0:
        return np.zeros((0, POSE_WIDTH[dim]))
    if dim == 2:
        out = gtsam.utilities.extractPose2(values)
        if out.shape[0] != n:
            raise ValueError(f"values hold {out.shape[0]} poses, expected {n}")
        return np.asarray(out, float)
    m = np.asarray(gtsam.utilities.extractPose3(values), float)
    if m.shape[0] != n:
        raise ValueError(f"values hold {m.shape[0]} poses, expected {n}")
    return np.column_stack([m[:, 9:12], rotmat_to_quat(m[:, :9].reshape(-1, 3, 3))])


def gtsam_information(dim: int, info: np.ndarray) -> np.ndarray:
    """Information in gtsam tangent order (identity for 2D; (rot, trans) permutation for 3D)."""
    info = np.asarray(info, float)
    return info if dim == 2 else info[..., _PERM_3D[:, None], _PERM_3D[None, :]]


class NoiseCache:
    """Gaussian noise models keyed by their information matrix: graphs often share a few distinct ones."""

    def __init__(self, dim: int):
        self.dim = dim
        self._cache: dict[bytes, object] = {}

    def __call__(self, info: np.ndarray):
        info = np.ascontiguousarray(info, dtype=float)
        key = info.tobytes()
        nm = self._cache.get(key)
        if nm is None:
            nm = gtsam.noiseModel.Gaussian.Information(gtsam_information(self.dim, info))
            self._cache[key] = nm
        return nm


def between_factors(data: PoseGraphData, idx: np.ndarray, a: np.ndarray, b: np.ndarray,
                    info_scale: np.ndarray | None = None, cache: NoiseCache | None = None) -> list:
    """Gaussian BetweenFactors for edges `idx` (data order), with node positions a, b of all edges."""
    cache = cache or NoiseCache(data.dim)
    cls = gtsam.BetweenFactorPose2 if data.dim == 2 else gtsam.BetweenFactorPose3
    out = []
    for n, e in enumerate(np.asarray(idx, np.int64).tolist()):
        info = data.information[e] if info_scale is None else data.information[e] * info_scale[n]
        out.append(cls(int(a[e]), int(b[e]), to_pose(data.dim, data.measurements[e]), cache(info)))
    return out


def anchor_nodes(data: PoseGraphData) -> np.ndarray:
    """Positions of the anchored nodes: the file's FIX vertices, else the first node."""
    if len(data.fixed):
        return data.index_of(data.fixed)
    return np.zeros(1 if data.num_nodes else 0, np.int64)


def prior_factors(data: PoseGraphData, anchors: np.ndarray, poses: np.ndarray, sigma: float) -> list:
    """Tight priors holding the anchor nodes at `poses[anchor]` (identity where no guess exists)."""
    d = TANGENT_DIM[data.dim]
    nm = gtsam.noiseModel.Isotropic.Sigma(d, sigma)
    cls = gtsam.PriorFactorPose2 if data.dim == 2 else gtsam.PriorFactorPose3
    out = []
    for k in np.asarray(anchors, np.int64).tolist():
        p = poses[k]
        pose = (gtsam.Pose2() if data.dim == 2 else gtsam.Pose3()) if np.isnan(p).any() else to_pose(data.dim, p)
        out.append(cls(int(k), pose, nm))
    return out


def graph_of(factors) -> gtsam.NonlinearFactorGraph:
    g = gtsam.NonlinearFactorGraph()
    for f in factors:
        g.add(f)
    return g


def squared_residuals(factors: list, values: gtsam.Values) -> np.ndarray:
    """Squared Mahalanobis residuals r^2 = 2 * error of Gaussian factors at `values`."""
    return np.fromiter((2.0 * f.error(values) for f in factors), dtype=float, count=len(factors))
