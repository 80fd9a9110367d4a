"""Squared Mahalanobis residuals of every loop closure at once, in numpy.

The robust batch solve (graph.robust) tests every loop against its threshold after each GNC step, screen and
re-solve; evaluating gtsam factors one by one from Python costs ~2 us per factor, 0.1 s per pass on w10000's
54k loops and several seconds per solve. Planar graphs are evaluated here in one vectorised pass with gtsam's own
conventions (BetweenFactorPose2: error = Logmap(z^-1 * (x_a^-1 * x_b)), r^2 = e^T Lambda e, the same numbers to
rounding: tests/graph/test_residuals.py); 3D graphs fall back to the factors.
"""
from __future__ import annotations

import gtsam
import numpy as np

from graph.factors import squared_residuals
from graph.model import PoseGraphData


def _pose2_logmap(t: np.ndarray, th: np.ndarray) -> np.ndarray:
    """gtsam Pose2::Logmap of (N, 2) translations and (N,) angles in (-pi, pi]."""
    out = np.column_stack([t, th])
    big = np.abs(th) >= 1e-10
    if big.any():
        w, tb = th[big], t[big]
        c, s = np.cos(w), np.sin(w)
        c1 = c - 1.0
        det = c1 * c1 + s * s
        # R^-1 t - t, then rotated by +90 degrees
        ux, uy = c * tb[:, 0] + s * tb[:, 1] - tb[:, 0], -s * tb[:, 0] + c * tb[:, 1] - tb[:, 1]
        out[big, 0] = (w / det) * -uy
        out[big, 1] = (w / det) * ux
    return out


class LoopResiduals:
    """r^2 of a fixed list of Gaussian loop factors at any `gtsam.Values` holding keys 0..n-1."""

    def __init__(self, dim: int, factors: list, a: np.ndarray | None = None, b: np.ndarray | None = None,
                 z: np.ndarray | None = None, info: np.ndarray | None = None):
        self.dim = dim
        self.factors = factors
        self.a, self.b, self.z, self.info = a, b, z, info

    @classmethod
    def of_edges(cls, data: PoseGraphData, edges: np.ndarray, a: np.ndarray, b: np.ndarray, factors: list,
                 info_scale: np.ndarray | None = None) -> LoopResiduals:
        """The residuals of `factors`, built by graph.factors.between_factors from `edges` (data order, node
        positions a, b of all edges, information times `info_scale`): read from the arrays, not the factors."""
        if data.dim != 2 or not len(edges):
            return cls(data.dim, factors)
        edges = np.asarray(edges, np.int64)
        info = data.information[edges].astype(float)
        if info_scale is not None:
            info = info * np.asarray(info_scale, float)[:, None, None]
        return cls(2, factors, a[edges], b[edges], data.measurements[edges].astype(float), info)

    def subset(self, keep: np.ndarray) -> LoopResiduals:
        keep = np.asarray(keep, bool)
        factors = [f for f, k in zip(self.factors, keep.tolist()) if k]
        if self.z is None:
            return LoopResiduals(self.dim, factors)
        return LoopResiduals(self.dim, factors, self.a[keep], self.b[keep], self.z[keep], self.info[keep])

    def __len__(self) -> int:
        return len(self.factors)

    def __call__(self, values: gtsam.Values) -> np.ndarray:
        if self.z is None:
            return squared_residuals(self.factors, values)
        if not len(self.z):
            return np.zeros(0)
        x = np.asarray(gtsam.utilities.extractPose2(values), float)
        pa, pb = x[self.a], x[self.b]
        ca, sa = np.cos(pa[:, 2]), np.sin(pa[:, 2])
        dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
        hx = np.column_stack([ca * dx + sa * dy, -sa * dx + ca * dy])       # x_a^-1 * x_b: translation
        th_h = pb[:, 2] - pa[:, 2]                                         # ... and rotation
        cz, sz = np.cos(self.z[:, 2]), np.sin(self.z[:, 2])
        ex, ey = hx[:, 0] - self.z[:, 0], hx[:, 1] - self.z[:, 1]
        t = np.column_stack([cz * ex + sz * ey, -sz * ex + cz * ey])        # z^-1 * hx: translation
        d = th_h - self.z[:, 2]
        th = np.arctan2(np.sin(d), np.cos(d))
        e = _pose2_logmap(t, th)
        m = self.info
        return (m[:, 0, 0] * e[:, 0] ** 2 + m[:, 1, 1] * e[:, 1] ** 2 + m[:, 2, 2] * e[:, 2] ** 2
                + (m[:, 0, 1] + m[:, 1, 0]) * e[:, 0] * e[:, 1] + (m[:, 0, 2] + m[:, 2, 0]) * e[:, 0] * e[:, 2]
                + (m[:, 1, 2] + m[:, 2, 1]) * e[:, 1] * e[:, 2])
