"""First-order uncertainty of planar pose operations (compose, between, inverse) with their Jacobians.

Poses are (x, y, theta) as in `odometry.poses`; covariances are 3x3 in the same (x, y, theta) order, which is
also the tangent order of a GTSAM Pose2 for small motions.
"""
from __future__ import annotations

import math

import numpy as np

from odometry.shared.poses import between, compose


def compose_jacobians(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of compose(a, b) with respect to a and b (each 3x3)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    rbx, rby = c * b[0] - s * b[1], s * b[0] + c * b[1]
    ja = np.array([[1.0, 0.0, -rby], [0.0, 1.0, rbx], [0.0, 0.0, 1.0]])
    jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return ja, jb


def between_jacobians(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of between(a, b) = inverse(a) ⊕ b with respect to a and b (each 3x3)."""
    d = between(a, b)
    c, s = math.cos(a[2]), math.sin(a[2])
    ja = np.array([[-c, -s, d[1]], [s, -c, -d[0]], [0.0, 0.0, -1.0]])
    jb = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return ja, jb


def compose_with_covariance(a: np.ndarray, cov_a: np.ndarray, b: np.ndarray,
                            cov_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a ⊕ b and its covariance, a and b independent."""
    ja, jb = compose_jacobians(a, b)
    cov = ja @ cov_a @ ja.T + jb @ cov_b @ jb.T
    return compose(a, b), 0.5 * (cov + cov.T)


def between_with_covariance(a: np.ndarray, cov_a: np.ndarray, b: np.ndarray, cov_b: np.ndarray,
                            cross_ba: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """between(a, b) and its covariance; `cross_ba` = Cov(error_b, error_a) when the two are correlated."""
    ja, jb = between_jacobians(a, b)
    cov = ja @ cov_a @ ja.T + jb @ cov_b @ jb.T
    if cross_ba is not None:
        x = jb @ cross_ba @ ja.T
        cov = cov + x + x.T
    return between(a, b), 0.5 * (cov + cov.T)
