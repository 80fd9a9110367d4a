"""TUM trajectory files ("timestamp tx ty tz qx qy qz qw") and the conversions between planar poses and TUM rows.

Planar poses become tz = 0 and a pure-yaw quaternion; 3D poses are read back onto the ground plane by the heading of
the rotated x axis.
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.errors import ToolkitError
from odometry.shared.rotations import quat_to_rotmat, quat_to_yaw, rotmat_to_quat, yaw_to_quat


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


class TumFormatError(ToolkitError):
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
