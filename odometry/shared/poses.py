"""Planar poses (x, y, theta): composition, inversion, relative motion, unicycle arcs.

The one place for pose conventions. Arrays have shape (..., 3) with columns x, y, theta (radians,
counter-clockwise from +x). `compose(a, b)` is a ⊕ b: the pose b, given in a's frame, expressed in
the world. Integrating per-frame motions with `integrate` is seed 001's eq. (1)-(2) with the frame-to-frame
(R, T) expressed in the previous robot frame: p_k = p_{k-1} + R(theta_{k-1}) T_k, theta_k = theta_{k-1} + dtheta_k.
"""
from __future__ import annotations

import math

import numpy as np


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


# ---------------------------------------------------------------------------------------------------- unicycle arcs

def arc_chord(v: np.ndarray | float, omega: np.ndarray | float, dt: np.ndarray | float
              ) -> tuple[np.ndarray, np.ndarray]:
    """Chord length and heading change of a unicycle driving with constant speed v and yaw rate omega for dt
    (scalars or arrays). The chord leaves at half the heading change: v dt sin(h) / h with h = omega dt / 2, exact
    for an arc, with the straight-line limit."""
    dth = omega * dt
    half = 0.5 * dth
    small = np.abs(half) < 1e-9
    sinc = np.where(small, 1.0, np.sin(half) / np.where(small, 1.0, half))
    return v * dt * sinc, dth


def arc_step(pose: np.ndarray, v: np.ndarray, omega: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Exact unicycle motion over dt with constant v, omega (vectorised over poses and controls)."""
    pose = np.asarray(pose, dtype=float)
    th = pose[..., 2]
    chord, dth = arc_chord(v, omega, dt)
    ang = th + dth / 2
    return np.stack([pose[..., 0] + chord * np.cos(ang), pose[..., 1] + chord * np.sin(ang), wrap_angle(th + dth)], -1)


def integrate_arcs(v: np.ndarray, omega: np.ndarray, dt: np.ndarray | float, start: np.ndarray | None = None
                   ) -> np.ndarray:
    """Poses (N + 1, 3) from piecewise-constant controls (N,), exactly (vectorised, no drift from discretisation)."""
    v = np.asarray(v, dtype=float)
    omega = np.asarray(omega, dtype=float)
    dt = np.broadcast_to(np.asarray(dt, dtype=float), v.shape)
    s = np.zeros(3) if start is None else np.asarray(start, dtype=float)
    chord, dth = arc_chord(v, omega, dt)
    th = s[2] + np.concatenate([[0.0], np.cumsum(dth)])
    ang = th[:-1] + dth / 2
    xy = s[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(np.column_stack([chord * np.cos(ang),
                                                                             chord * np.sin(ang)]), axis=0)])
    return np.column_stack([xy, wrap_angle(th)])
