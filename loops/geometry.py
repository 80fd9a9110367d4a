"""Image-plane transforms between matched keypoints for loop verification: similarity and affine estimators, their
plausibility test, a few deterministic RANSAC iterations over them (the shared loop of `odometry.shared.ransac`),
and the image overlap a fitted transform implies.

Points are (K, 2) arrays; a fitted transform is returned as `predict(points) -> points` (image a -> image b).
"""
from __future__ import annotations

import enum
from typing import Callable

import numpy as np

from odometry.shared.ransac import find_consensus, refit_if_not_worse, sample_subsets

Predict = Callable[[np.ndarray], np.ndarray]


class GeometryModel(enum.Enum):
    """Transform fitted by the RANSAC check of a loop candidate."""

    SIMILARITY = "similarity"  # rotation + scale + translation (downward camera over a planar floor)
    AFFINE = "affine"          # general images: tolerates moderate viewpoint change


# ---------------------------------------------------------------------------------------------- estimators
def fit_similarity(p: np.ndarray, q: np.ndarray, w: np.ndarray) -> tuple[complex, complex]:
    """Weighted least-squares similarity q ~ a p + b in complex form (a = scale * e^(i angle))."""
    pc, qc = p[:, 0] + 1j * p[:, 1], q[:, 0] + 1j * q[:, 1]
    if w.sum() <= 0:
        w = np.ones(len(w))
    sw = w.sum()
    pm, qm = np.dot(w, pc) / sw, np.dot(w, qc) / sw
    den = np.dot(w, np.abs(pc - pm) ** 2)
    a = np.dot(w, np.conj(pc - pm) * (qc - qm)) / den if den > 0 else 1.0 + 0j
    return a, qm - a * pm


def similarity_through(p: np.ndarray, q: np.ndarray, j: np.ndarray) -> tuple[complex, complex]:
    """The similarity through two correspondences j = (j0, j1)."""
    a0 = (q[j[1], 0] - q[j[0], 0] + 1j * (q[j[1], 1] - q[j[0], 1])) / \
         (p[j[1], 0] - p[j[0], 0] + 1j * (p[j[1], 1] - p[j[0], 1]))
    return a0, (q[j[0], 0] + 1j * q[j[0], 1]) - a0 * (p[j[0], 0] + 1j * p[j[0], 1])


def apply_similarity(a: complex, b: complex) -> Predict:
    def predict(x: np.ndarray) -> np.ndarray:
        z = a * (x[:, 0] + 1j * x[:, 1]) + b
        return np.column_stack([z.real, z.imag])
    return predict


def fit_affine(p: np.ndarray, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares affine transform (3, 2): q ~ [p, 1] @ M."""
    ph = np.concatenate([p, np.ones((len(p), 1))], axis=1)
    sw = np.sqrt(np.maximum(w, 1e-12))[:, None]
    M, *_ = np.linalg.lstsq(ph * sw, q * sw, rcond=None)
    return M


def affine_through(p: np.ndarray, q: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The affine transform through three correspondences j."""
    ph = np.concatenate([p[j], np.ones((3, 1))], axis=1)
    return np.linalg.solve(ph, q[j])


def apply_affine(M: np.ndarray) -> Predict:
    def predict(x: np.ndarray) -> np.ndarray:
        return x @ M[:2] + M[2]
    return predict


def plausible_linear(L: np.ndarray, scale_range: tuple[float, float], max_anisotropy: float) -> np.ndarray:
    """Which linear parts L (..., 2, 2) of fitted transforms are a plausible view change: no mirroring, overall
    scale sqrt|det| within scale_range, singular-value ratio <= max_anisotropy. Random matches fit arbitrary
    transforms (half of them mirrored, many squashing the points onto a line); real view changes do not."""
    a, b, c, d = L[..., 0, 0], L[..., 0, 1], L[..., 1, 0], L[..., 1, 1]
    det = a * d - b * c
    fro2 = a * a + b * b + c * c + d * d
    # singular values s1 >= s2: s1^2 + s2^2 = fro2, s1 s2 = det
    disc = np.sqrt(np.maximum(fro2 * fro2 - 4 * det * det, 0.0))
    s1 = np.sqrt(np.maximum(0.5 * (fro2 + disc), 0.0))
    s2 = np.sqrt(np.maximum(0.5 * (fro2 - disc), 0.0))
    scale = np.sqrt(np.abs(det))
    return (det > 0) & (scale >= scale_range[0]) & (scale <= scale_range[1]) & (s1 <= max_anisotropy * s2)


# ---------------------------------------------------------------------------------------------- hypotheses
def similarity_residuals(xa: np.ndarray, xb: np.ndarray, samples: np.ndarray,
                         scale_range: tuple[float, float]) -> np.ndarray:
    """Squared residuals (H, K) of every point under the similarity through each 2-point sample; inf for a
    degenerate sample or a scale outside scale_range."""
    pc, qc = xa[:, 0] + 1j * xa[:, 1], xb[:, 0] + 1j * xb[:, 1]
    p1, p2 = pc[samples[:, 0]], pc[samples[:, 1]]
    q1, q2 = qc[samples[:, 0]], qc[samples[:, 1]]
    ok = np.abs(p2 - p1) > 1e-6
    a = np.where(ok, (q2 - q1) / np.where(ok, p2 - p1, 1), 0)
    ok &= (np.abs(a) >= scale_range[0]) & (np.abs(a) <= scale_range[1])
    b = q1 - a * p1
    r2 = np.abs(a[:, None] * pc[None, :] + b[:, None] - qc[None, :]) ** 2
    r2[~ok] = np.inf
    return r2


def affine_residuals(xa: np.ndarray, xb: np.ndarray, samples: np.ndarray, scale_range: tuple[float, float],
                     max_anisotropy: float) -> np.ndarray:
    """Squared residuals (H, K) of every point under the affine transform through each 3-point sample; inf for a
    degenerate sample or an implausible transform (`plausible_linear`)."""
    k = len(xa)
    ph = np.concatenate([xa, np.ones((k, 1))], axis=1)          # (k, 3)
    A = ph[samples]                                              # (it, 3, 3)
    B = xb[samples]                                              # (it, 3, 2)
    det = np.linalg.det(A)
    ok = np.abs(det) > 1e-3
    M = np.zeros((len(samples), 3, 2))
    if ok.any():
        M[ok] = np.linalg.solve(A[ok], B[ok])
    ok &= plausible_linear(np.swapaxes(M[:, :2], 1, 2), scale_range, max_anisotropy)
    pred = np.einsum("kc,icd->ikd", ph, M)                       # (it, k, 2)
    r2 = np.sum((pred - xb[None]) ** 2, axis=2)
    r2[~ok] = np.inf
    return r2


def ransac_transform(xa: np.ndarray, xb: np.ndarray, w: np.ndarray, model: GeometryModel, iterations: int,
                     threshold: float, seed: int = 0, scale_range: tuple[float, float] = (0.0, np.inf),
                     max_anisotropy: float = np.inf) -> tuple[np.ndarray, Predict | None]:
    """(inlier mask, fitted transform xa -> xb or None) after a few vectorised RANSAC iterations scored by inlier
    weight, refined once by weighted least squares on the inliers (kept when plausible and not worse). Hypotheses
    whose scale (or, for affine, mirroring / anisotropy) is implausible are discarded. Deterministic for a given
    input and seed: the generator is seeded with seed + number of matches."""
    k = len(xa)
    similarity = model is GeometryModel.SIMILARITY
    need = 2 if similarity else 3
    none = np.zeros(k, dtype=bool), None
    if k < need + 1:
        return none
    rng = np.random.default_rng(seed + k)
    thr2 = threshold * threshold

    def evaluate(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r2 = (similarity_residuals(xa, xb, samples, scale_range) if similarity
              else affine_residuals(xa, xb, samples, scale_range, max_anisotropy))
        inl = r2 < thr2
        return inl @ w, inl

    best = find_consensus(lambda n: sample_subsets(rng, n, k, need), evaluate, iterations)
    if best is None or best.inliers.sum() < need:
        return none
    mask = best.inliers

    def refit(m: np.ndarray) -> tuple[Predict, np.ndarray] | None:
        if similarity:
            a_r, b_r = fit_similarity(xa[m], xb[m], w[m])
            predict, plausible = apply_similarity(a_r, b_r), scale_range[0] <= abs(a_r) <= scale_range[1]
        else:
            M = fit_affine(xa[m], xb[m], w[m])
            predict, plausible = apply_affine(M), bool(plausible_linear(M[:2].T, scale_range, max_anisotropy))
        if not plausible:
            return None
        return predict, np.sum((predict(xa) - xb) ** 2, axis=1) < thr2

    refined = refit_if_not_worse(mask, refit, lambda m: m @ w)
    if refined is not None:
        return refined[1], refined[0]
    j = best.hypotheses[best.index]
    if similarity:
        return mask, apply_similarity(*similarity_through(xa, xb, j))
    return mask, apply_affine(affine_through(xa, xb, j))


# ---------------------------------------------------------------------------------------------- overlap
def _clip_to_box(poly: list[tuple[float, float]], w: float, h: float) -> list[tuple[float, float]]:
    """Sutherland-Hodgman clipping of a convex polygon to the box [0, w] x [0, h]."""
    for axis, bound, keep_below in ((0, 0.0, False), (0, w, True), (1, 0.0, False), (1, h, True)):
        out: list[tuple[float, float]] = []
        n = len(poly)
        for k in range(n):
            p, q = poly[k], poly[(k + 1) % n]
            p_in = p[axis] <= bound if keep_below else p[axis] >= bound
            q_in = q[axis] <= bound if keep_below else q[axis] >= bound
            if p_in:
                out.append(p)
            if p_in != q_in:
                t = (bound - p[axis]) / (q[axis] - p[axis])
                out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
        poly = out
        if not poly:
            break
    return poly


def _area(poly: list[tuple[float, float]]) -> float:
    n = len(poly)
    return 0.5 * abs(sum(poly[k][0] * poly[(k + 1) % n][1] - poly[(k + 1) % n][0] * poly[k][1] for k in range(n)))


def transform_overlap(predict: Predict, size_a: tuple[int, int], size_b: tuple[int, int]) -> float:
    """Overlap J (intersection over union) of image b's rectangle and image a's rectangle mapped by the fitted
    transform a -> b. For a downward camera over a planar floor (similarity transform) this is the floor-footprint
    overlap of the two views, the very quantity that defines a loop (seed 001 eq. 3), estimated from the images.
    The mapped rectangle is a parallelogram (similarity or affine): convex clipping in plain Python, ~4x faster
    than a shapely intersection on such small polygons."""
    (wa, ha), (wb, hb) = size_a, size_b
    ca = np.array([[0.0, 0.0], [wa, 0.0], [wa, ha], [0.0, ha]])
    quad = [(float(x), float(y)) for x, y in predict(ca)]
    area_a = _area(quad)
    if not np.isfinite(area_a) or area_a <= 0:
        return 0.0
    clipped = _clip_to_box(quad, float(wb), float(hb))
    inter = _area(clipped) if len(clipped) >= 3 else 0.0
    union = area_a + float(wb) * float(hb) - inter
    return float(inter / union) if union > 0 else 0.0
