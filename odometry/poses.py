"""Planar poses (x, y, theta): composition, inversion, relative motion, and TUM 3D conversions.

The one place for pose conventions. Arrays have shape (..., 3) with columns x, y, theta (radians,
counter-clockwise from +x). `compose(a, b)` is a ⊕ b: the pose b, given in a's frame, expressed in
the world. Integrating per-frame motions with `integrate` is seed 001's eq. (1)-(2) with the frame-to-frame
(R, T) expressed in the previous robot frame: p_k = p_{k-1} + R(theta_{k-1}) T_k, theta_k = theta_{k-1} + dtheta_k.

TUM rows are "timestamp tx ty tz qx qy qz qw"; planar poses become tz = 0 and a pure-yaw quaternion.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from odometry.atomic_io import atomic_write_text


def wrap_angle(a: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi if isinstance(a, np.ndarray) else \
        (float(a) + math.pi) % (2.0 * math.pi) - math.pi


def rot2(theta: np.ndarray | float) -> np.ndarray:
    """2x2 rotation matrices, shape (..., 2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b for poses (..., 3); broadcasts."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], -1)


def inverse(a: np.ndarray) -> np.ndarray:
    """⊖a: the world origin seen from pose a."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], -1)


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """⊖a ⊕ b: pose b expressed in the frame of pose a (the relative motion from a to b)."""
    return compose(inverse(a), b)


def transform_points(pose: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Map points (N, 2) from the frame of `pose` (3,) into the world."""
    pose = np.asarray(pose, dtype=float)
    return np.asarray(pts, dtype=float) @ rot2(pose[2]).T + pose[:2]


def integrate(deltas: np.ndarray, start: np.ndarray | None = None) -> np.ndarray:
    """Chain relative motions (N, 3) into N + 1 poses starting at `start` (default origin).

    Vectorised: headings are a cumulative sum, positions a cumulative sum of rotated steps.
    """
    d = np.asarray(deltas, dtype=float).reshape(-1, 3)
    s = np.zeros(3) if start is None else np.asarray(start, dtype=float)
    theta = s[2] + np.concatenate([[0.0], np.cumsum(d[:, 2])])
    c, sn = np.cos(theta[:-1]), np.sin(theta[:-1])
    steps = np.stack([c * d[:, 0] - sn * d[:, 1], sn * d[:, 0] + c * d[:, 1]], -1)
    xy = s[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    return np.column_stack([xy, wrap_angle(theta)])


def relative_motions(poses: np.ndarray) -> np.ndarray:
    """Per-step motions (N-1, 3) between consecutive poses (N, 3); `integrate` inverts it."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    return between(p[:-1], p[1:])


def to_matrix(pose: np.ndarray) -> np.ndarray:
    """SE(2) homogeneous matrices (..., 3, 3)."""
    pose = np.asarray(pose, dtype=float)
    m = np.zeros(pose.shape[:-1] + (3, 3))
    m[..., :2, :2] = rot2(pose[..., 2])
    m[..., :2, 2] = pose[..., :2]
    m[..., 2, 2] = 1.0
    return m


def from_matrix(m: np.ndarray) -> np.ndarray:
    m = np.asarray(m, dtype=float)
    return np.stack([m[..., 0, 2], m[..., 1, 2], np.arctan2(m[..., 1, 0], m[..., 0, 0])], -1)


# ---------------------------------------------------------------------------------------------------- 3D / TUM

def yaw_to_quat(theta: np.ndarray | float) -> np.ndarray:
    """Pure-yaw quaternions in TUM order (qx, qy, qz, qw), shape (..., 4)."""
    t = np.asarray(theta, dtype=float)
    z = np.zeros_like(t)
    return np.stack([z, z, np.sin(t / 2), np.cos(t / 2)], -1)


def quat_to_rotmat(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) from quaternions (..., 4) in (qx, qy, qz, qw) order; normalises."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def rotmat_to_quat(r: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) in (qx, qy, qz, qw) order with qw >= 0, from rotation matrices (..., 3, 3)."""
    r = np.asarray(r, dtype=float)
    m = r.reshape(-1, 3, 3)
    out = np.empty((m.shape[0], 4))
    tr = np.trace(m, axis1=1, axis2=2)
    for i, (mi, t) in enumerate(zip(m, tr)):  # branchy but small: only used on file I/O, not hot paths
        if t > 0:
            s = math.sqrt(t + 1.0) * 2
            out[i] = [(mi[2, 1] - mi[1, 2]) / s, (mi[0, 2] - mi[2, 0]) / s, (mi[1, 0] - mi[0, 1]) / s, 0.25 * s]
        elif mi[0, 0] > mi[1, 1] and mi[0, 0] > mi[2, 2]:
            s = math.sqrt(1.0 + mi[0, 0] - mi[1, 1] - mi[2, 2]) * 2
            out[i] = [0.25 * s, (mi[0, 1] + mi[1, 0]) / s, (mi[0, 2] + mi[2, 0]) / s, (mi[2, 1] - mi[1, 2]) / s]
        elif mi[1, 1] > mi[2, 2]:
            s = math.sqrt(1.0 + mi[1, 1] - mi[0, 0] - mi[2, 2]) * 2
            out[i] = [(mi[0, 1] + mi[1, 0]) / s, 0.25 * s, (mi[1, 2] + mi[2, 1]) / s, (mi[0, 2] - mi[2, 0]) / s]
        else:
            s = math.sqrt(1.0 + mi[2, 2] - mi[0, 0] - mi[1, 1]) * 2
            out[i] = [(mi[0, 2] + mi[2, 0]) / s, (mi[1, 2] + mi[2, 1]) / s, 0.25 * s, (mi[1, 0] - mi[0, 1]) / s]
    out *= np.where(out[:, 3:4] < 0, -1.0, 1.0)
    return out.reshape(r.shape[:-2] + (4,))


def quat_to_yaw(q: np.ndarray) -> np.ndarray:
    """Heading of the rotated x axis projected on the ground plane, from (qx, qy, qz, qw) quaternions."""
    r = quat_to_rotmat(q)
    return np.arctan2(r[..., 1, 0], r[..., 0, 0])


def se2_to_tum(poses: np.ndarray) -> np.ndarray:
    """Planar poses (N, 3) -> TUM pose columns (N, 7): tx ty tz qx qy qz qw, with tz = 0."""
    p = np.asarray(poses, dtype=float).reshape(-1, 3)
    return np.column_stack([p[:, :2], np.zeros(len(p)), yaw_to_quat(p[:, 2])])


def tum_to_se2(tum: np.ndarray) -> np.ndarray:
    """TUM pose columns (N, 7) -> planar poses (N, 3): x, y and the ground-plane heading."""
    t = np.asarray(tum, dtype=float).reshape(-1, 7)
    return np.column_stack([t[:, 0], t[:, 1], quat_to_yaw(t[:, 3:7])])


def se3_matrices_to_tum(m: np.ndarray) -> np.ndarray:
    """4x4 (or 3x4) pose matrices (N, 3|4, 4) -> TUM pose columns (N, 7)."""
    m = np.asarray(m, dtype=float)
    return np.column_stack([m[:, :3, 3], rotmat_to_quat(m[:, :3, :3])])


def tum_to_se3_matrices(tum: np.ndarray) -> np.ndarray:
    t = np.asarray(tum, dtype=float).reshape(-1, 7)
    m = np.tile(np.eye(4), (len(t), 1, 1))
    m[:, :3, :3] = quat_to_rotmat(t[:, 3:7])
    m[:, :3, 3] = t[:, :3]
    return m


class TumFormatError(ValueError):
    """A malformed TUM trajectory file; the message names the file and line."""


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory: (timestamps (N,), poses (N, 7) = tx ty tz qx qy qz qw).

    Blank lines and '#' comments are skipped; commas are accepted as separators.
    """
    path = Path(path)
    ts, rows = [], []
    with open(path, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            s = line.split("#", 1)[0].strip()
            if not s:
                continue
            parts = s.replace(",", " ").split()
            if len(parts) != 8:
                raise TumFormatError(f"{path}:{lineno}: expected 8 columns 'timestamp tx ty tz qx qy qz qw', "
                                     f"got {len(parts)}")
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                raise TumFormatError(f"{path}:{lineno}: non-numeric value in {s!r}") from None
            if not all(math.isfinite(v) for v in vals):
                raise TumFormatError(f"{path}:{lineno}: NaN or infinite value in {s!r}")
            if abs(sum(v * v for v in vals[4:8])) < 1e-12:
                raise TumFormatError(f"{path}:{lineno}: zero quaternion")
            ts.append(vals[0])
            rows.append(vals[1:])
    return np.asarray(ts, dtype=float), np.asarray(rows, dtype=float).reshape(-1, 7)


def format_tum(timestamps: np.ndarray, tum: np.ndarray) -> str:
    t = np.asarray(timestamps, dtype=float).reshape(-1)
    p = np.asarray(tum, dtype=float).reshape(-1, 7)
    if len(t) != len(p):
        raise ValueError(f"{len(t)} timestamps for {len(p)} poses")
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    lines += [f"{ti:.6f} " + " ".join(f"{v:.9f}" for v in row) for ti, row in zip(t, p)]
    return "\n".join(lines) + "\n"


def write_tum(path: str | os.PathLike, timestamps: np.ndarray, poses: np.ndarray) -> None:
    """Write a TUM file atomically. `poses` is (N, 7) TUM columns or (N, 3) planar poses."""
    p = np.asarray(poses, dtype=float)
    if p.ndim == 2 and p.shape[1] == 3:
        p = se2_to_tum(p)
    atomic_write_text(path, format_tum(timestamps, p))
