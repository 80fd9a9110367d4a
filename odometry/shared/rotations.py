"""Rotations: quaternions in TUM / Rerun order (qx, qy, qz, qw) and the small camera tilt (roll, pitch).

Quaternion order differs between libraries: TUM files, Rerun and scipy use xyzw; evo's arrays use wxyz; GTSAM's
Rot3.Quaternion takes (w, x, y, z). Everything in this toolkit is xyzw, converted at the library boundary.
"""
from __future__ import annotations

import math

import numpy as np


def tilt_matrix(roll: float, pitch: float) -> np.ndarray:
    """Rotation of the viewing rays for a camera tilted by roll (about its x axis) then pitch (about its y axis)."""
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return ry @ rx


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
