"""Planar rigid motion between matched floor points: centroid-removed SVD (Kabsch), RANSAC (the shared loop of
`odometry.shared.ransac` over 2-point hypotheses), covariance.

Convention: `fit` finds (dx, dy, dtheta) such that dst ≈ R(dtheta) src + (dx, dy). For a downward camera, with
src the floor points of frame k (base frame k) and dst the same floor points in base frame k-1, this motion is
the robot's motion from k-1 to k in the compose convention of `odometry.shared.poses`:
pose_k = compose(pose_{k-1}, (dx, dy, dtheta)).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from odometry.height import Height
from odometry.shared.ransac import find_consensus, refine_iteratively, sample_pairs


@dataclass
class RigidFit:
    """A robust rigid fit.

    Attributes:
        delta: (3,) dx, dy, dtheta with dst ≈ R src + t.
        covariance: (3, 3) covariance of delta from the inlier residuals and point geometry.
        inliers: (N,) bool mask over the input pairs.
        rms: root-mean-square inlier residual (same unit as the points).
        sigma: per-axis residual standard deviation used for the covariance.
        height: the camera height (`odometry.height.Height`) of the `src` frame when a refinement measured it
            (None otherwise).
    """

    delta: np.ndarray
    covariance: np.ndarray
    inliers: np.ndarray
    rms: float
    sigma: float
    height: Height | None = None

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())

    @property
    def inlier_ratio(self) -> float:
        return float(self.inliers.mean()) if len(self.inliers) else 0.0


def kabsch_2d(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Least-squares rotation + translation (dx, dy, dtheta) with dst ≈ R src + t (seed 001 §IV-D).

    Centroids are removed, the 2x2 cross-covariance is decomposed by SVD, and a reflection is excluded by the
    sign of det(V U^T). Needs at least 2 distinct points.
    """
    src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 2)
    if len(src) != len(dst) or len(src) < 2:
        raise ValueError(f"kabsch_2d needs >= 2 matched pairs, got {len(src)} and {len(dst)}")
    if weights is None:
        w = np.full(len(src), 1.0 / len(src))
    else:
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        w = w / w.sum()
    cs = w @ src
    cd = w @ dst
    h = (src - cs).T @ ((dst - cd) * w[:, None])  # sum w p q^T
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, d]) @ u.T
    t = cd - r @ cs
    return np.array([t[0], t[1], math.atan2(r[1, 0], r[0, 0])])


def apply(delta: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """R(dtheta) pts + (dx, dy) for points (N, 2)."""
    c, s = math.cos(delta[2]), math.sin(delta[2])
    return pts @ np.array([[c, s], [-s, c]]) + delta[:2]


def rigid_covariance(src: np.ndarray, delta: np.ndarray, sigma: float) -> np.ndarray:
    """Covariance of a least-squares rigid fit: sigma^2 (J^T J)^-1 with residual r_i = R p_i + t - q_i.

    sigma is the per-axis standard deviation of a residual (the noise of both point sets together).
    """
    p = apply(np.array([0.0, 0.0, delta[2]]), np.asarray(src, dtype=np.float64).reshape(-1, 2))
    n = len(p)
    sx, sy = p[:, 0].sum(), p[:, 1].sum()
    jtj = np.array([[n, 0.0, -sy], [0.0, n, sx], [-sy, sx, float((p * p).sum())]])
    cov = sigma * sigma * np.linalg.inv(jtj)
    return 0.5 * (cov + cov.T)


def _two_point_hypotheses(src: np.ndarray, dst: np.ndarray, i: np.ndarray, j: np.ndarray,
                          min_separation: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact rigid motions through pairs (i, j): rotation from the segment directions, translation via the
    midpoints (the 2-point Kabsch solution). Returns cos, sin, t (K, 2) and drops near-degenerate pairs."""
    ps, pd = src[j] - src[i], dst[j] - dst[i]
    ls, ld = np.hypot(ps[:, 0], ps[:, 1]), np.hypot(pd[:, 0], pd[:, 1])
    ok = (ls > min_separation) & (ld > min_separation)
    ps, pd, ls, ld = ps[ok], pd[ok], ls[ok], ld[ok]
    c = (ps[:, 0] * pd[:, 0] + ps[:, 1] * pd[:, 1]) / (ls * ld)
    s = (ps[:, 0] * pd[:, 1] - ps[:, 1] * pd[:, 0]) / (ls * ld)
    ms = 0.5 * (src[i[ok]] + src[j[ok]])
    md = 0.5 * (dst[i[ok]] + dst[j[ok]])
    t = md - np.column_stack([c * ms[:, 0] - s * ms[:, 1], s * ms[:, 0] + c * ms[:, 1]])
    return c, s, t


def ransac_rigid_2d(src: np.ndarray, dst: np.ndarray, threshold: float, *, rng: np.random.Generator,
                    max_iterations: int = 200, confidence: float = 0.999, min_separation: float | None = None,
                    sigma_floor: float = 0.0, refine_iterations: int = 3, batch: int = 32) -> RigidFit | None:
    """RANSAC over 2-point rigid hypotheses, then Kabsch refinement on all inliers (re-selected each time).

    Args:
        src, dst: matched points (N, 2); the fit maps src onto dst.
        threshold: inlier distance (same unit as the points).
        rng: the random generator (pass a seeded one: results are then deterministic).
        max_iterations: hypothesis budget; the loop stops earlier once `confidence` is reached.
        min_separation: reject samples whose two points are closer than this (default 5 x threshold): the angle
            of a short segment is noise.
        sigma_floor: lower bound on the residual standard deviation used for the covariance (e.g. LK precision).
        refine_iterations: Kabsch + inlier re-selection rounds.
        batch: hypotheses scored together (vectorised).

    Returns None when there are fewer than 2 pairs or no hypothesis has 2 inliers.
    """
    src = np.asarray(src, dtype=np.float64).reshape(-1, 2)
    dst = np.asarray(dst, dtype=np.float64).reshape(-1, 2)
    n = len(src)
    if n < 2 or len(dst) != n:
        return None
    min_sep = 5.0 * threshold if min_separation is None else min_separation
    thr2 = threshold * threshold

    def draw(k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        i, j = sample_pairs(rng, n, k)
        return _two_point_hypotheses(src, dst, i, j, min_sep)

    def evaluate(h: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        c, s, t = h
        # residuals of every point under every hypothesis: (K, N)
        px = c[:, None] * src[None, :, 0] - s[:, None] * src[None, :, 1] + t[:, 0:1] - dst[None, :, 0]
        py = s[:, None] * src[None, :, 0] + c[:, None] * src[None, :, 1] + t[:, 1:2] - dst[None, :, 1]
        inliers = (px * px + py * py) < thr2
        return inliers.sum(1), inliers

    best = find_consensus(draw, evaluate, max_iterations, batch=batch, better_than=1, confidence=confidence,
                          n_data=n, sample_size=2)
    if best is None:
        return None
    c, s, t = best.hypotheses
    h = best.index
    delta0 = np.array([t[h, 0], t[h, 1], math.atan2(s[h], c[h])])

    def inliers_of(delta: np.ndarray) -> np.ndarray:
        r = apply(delta, src) - dst
        return (r * r).sum(1) < thr2

    delta, inl = refine_iteratively(delta0, inliers_of, lambda m: kabsch_2d(src[m], dst[m]), refine_iterations,
                                    2, n)
    if inl.sum() < 2:
        return None
    r = apply(delta, src[inl]) - dst[inl]
    m = int(inl.sum())
    rss = float((r * r).sum())
    rms = math.sqrt(rss / m)
    dof = max(2 * m - 3, 1)
    sigma = max(math.sqrt(rss / dof), sigma_floor)
    return RigidFit(delta=delta, covariance=rigid_covariance(src[inl], delta, sigma), inliers=inl, rms=rms,
                    sigma=sigma)
