"""Geometric consistency of tentative matches: DISTRAT (log-distance-ratio statistics, Lepsoy et al. 2011, as
used by MPEG CDVS) followed by a few deterministic RANSAC iterations of a similarity or affine transform.

DISTRAT needs no model of the transform: for inlier pairs the log ratio of distances between two matched
points in image A and in image B is nearly constant (the log scale change); for outliers it follows the
distribution of the difference of two independent log distances, which is estimated from the two point sets
themselves. A chi-square goodness-of-fit test says whether any inliers are present; the principal eigenvector of
the histogram excess (observed - scaled outlier model) over the pairs picks them.
"""
from __future__ import annotations

import functools
from typing import Callable

import numpy as np

from loops.cdvs.params import GeometryModel

_LOG_STEP = 0.2
_N_LOGD = 35          # histogram of log distances, bin centres 0 .. 6.8
_N_LDR = 25           # LDR histogram, bin centres -2.4 .. 2.4
_SMOOTH = np.array([0.0404, 0.9192, 0.0404])


def _ldr_bins(v: np.ndarray) -> np.ndarray:
    edge0 = -2.4 - _LOG_STEP / 2
    return np.clip(np.floor((v + 1e-5 - edge0) / _LOG_STEP), 0, _N_LDR - 1).astype(np.int64)


@functools.lru_cache(maxsize=512)
def _pairs(k: int) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs i < j of k matches (cached: the geometric check runs on the same few sizes again and again)."""
    i, j = np.triu_indices(k, 1)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j


def distrat_inliers(xa: np.ndarray, xb: np.ndarray, chi2_threshold: float) -> np.ndarray:
    """Indices of the matches (rows of xa, xb: (K, 2)) that DISTRAT finds geometrically consistent."""
    k = len(xa)
    if k < 3:
        return np.zeros(0, dtype=np.int64)
    i, j = _pairs(k)
    da = (xa[i, 0] - xa[j, 0]) ** 2 + (xa[i, 1] - xa[j, 1]) ** 2
    db = (xb[i, 0] - xb[j, 0]) ** 2 + (xb[i, 1] - xb[j, 1]) ** 2
    loga, logb = 0.5 * np.log(da + 1e-6), 0.5 * np.log(db + 1e-9)
    ldr = loga - logb
    # outlier model: distribution of (log dA - log dB) for independent pairs = correlation of the two histograms
    la = np.clip(np.rint(loga * (1.0 / _LOG_STEP)), 0, _N_LOGD - 1).astype(np.intp)
    lb = np.clip(np.rint(logb * (1.0 / _LOG_STEP)), 0, _N_LOGD - 1).astype(np.intp)
    ha = np.bincount(la, minlength=_N_LOGD).astype(np.float64)
    hb = np.bincount(lb, minlength=_N_LOGD).astype(np.float64)
    conv = np.convolve(ha, hb[::-1])                  # index m <-> difference (m - 34) * step
    centre = _N_LOGD - 1
    lo, hi = centre - _N_LDR // 2, centre + _N_LDR // 2
    model = conv[lo: hi + 1].copy()
    model[0] += conv[:lo].sum()                        # fold the tails into the end bins, as the LDR histogram does
    model[-1] += conv[hi + 1:].sum()
    model = np.convolve(model + 1e-8, _SMOOTH, mode="same")
    f = model / model.sum()
    bins = _ldr_bins(ldr)
    h = np.bincount(bins, minlength=_N_LDR).astype(np.float64)
    n = h.sum()
    n_eff = 5000.0 * (1.0 - np.exp(-n / 5000.0))
    chi2 = np.sum((h * n_eff / n - f * n_eff) ** 2 / (f * n_eff))
    if chi2 < chi2_threshold:
        return np.zeros(0, dtype=np.int64)
    m = f * n
    a = np.dot(h, m) / np.dot(m, m)
    diff = h - a * m
    dmax = diff.max()
    if dmax <= 0:
        return np.zeros(0, dtype=np.int64)
    g = np.zeros((k, k))
    g[i, j] = diff[bins]
    g += g.T
    u = g.sum(axis=1)
    nu = np.linalg.norm(u)
    if nu == 0:
        return np.zeros(0, dtype=np.int64)
    u /= nu
    # matrix-vector products via einsum: no BLAS call, so no thread pool spin-up on a busy machine
    for _ in range(4):
        v = np.einsum("ij,j->i", g, u)
        nv = np.linalg.norm(v)
        if nv == 0:
            return np.zeros(0, dtype=np.int64)
        v /= nv
        done = np.linalg.norm(v - u) < 1e-3
        u = v
        if done:
            break
    lam = np.linalg.norm(np.einsum("ij,j->i", g, u))
    n_in = min(int(lam / dmax) + 1, k)
    if u.sum() < 0:
        u = -u
    return np.sort(np.argsort(-u, kind="stable")[:n_in])


def _fit_similarity(p: np.ndarray, q: np.ndarray, w: np.ndarray) -> tuple[complex, complex]:
    pc, qc = p[:, 0] + 1j * p[:, 1], q[:, 0] + 1j * q[:, 1]
    if w.sum() <= 0:
        w = np.ones(len(w))
    sw = w.sum()
    pm, qm = np.dot(w, pc) / sw, np.dot(w, qc) / sw
    den = np.dot(w, np.abs(pc - pm) ** 2)
    a = np.dot(w, np.conj(pc - pm) * (qc - qm)) / den if den > 0 else 1.0 + 0j
    return a, qm - a * pm


def _apply_similarity(a: complex, b: complex) -> Callable[[np.ndarray], np.ndarray]:
    def predict(x: np.ndarray) -> np.ndarray:
        z = a * (x[:, 0] + 1j * x[:, 1]) + b
        return np.column_stack([z.real, z.imag])
    return predict


def _apply_affine(M: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    def predict(x: np.ndarray) -> np.ndarray:
        return x @ M[:2] + M[2]
    return predict


def _affine_ok(L: np.ndarray, scale_range: tuple[float, float], max_anisotropy: float) -> np.ndarray:
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


def ransac(xa: np.ndarray, xb: np.ndarray, w: np.ndarray, model: GeometryModel, iterations: int,
           threshold: float, seed: int = 0, scale_range: tuple[float, float] = (0.0, np.inf),
           max_anisotropy: float = np.inf) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray] | None]:
    """(inlier mask, fitted transform xa -> xb or None) after a few vectorised RANSAC iterations, refined once by
    weighted least squares on the inliers. Hypotheses whose scale (or, for affine, mirroring / anisotropy) is
    implausible are discarded (`_affine_ok`). Deterministic for a given input and seed."""
    k = len(xa)
    need = 2 if model is GeometryModel.SIMILARITY else 3
    none = np.zeros(k, dtype=bool), None
    if k < need + 1:
        return none
    rng = np.random.default_rng(seed + k)
    samples = np.argsort(rng.random((iterations, k)), axis=1)[:, :need]
    thr2 = threshold * threshold
    if model is GeometryModel.SIMILARITY:
        pc, qc = xa[:, 0] + 1j * xa[:, 1], xb[:, 0] + 1j * xb[:, 1]
        p1, p2 = pc[samples[:, 0]], pc[samples[:, 1]]
        q1, q2 = qc[samples[:, 0]], qc[samples[:, 1]]
        ok = np.abs(p2 - p1) > 1e-6
        a = np.where(ok, (q2 - q1) / np.where(ok, p2 - p1, 1), 0)
        ok &= (np.abs(a) >= scale_range[0]) & (np.abs(a) <= scale_range[1])
        b = q1 - a * p1
        r2 = np.abs(a[:, None] * pc[None, :] + b[:, None] - qc[None, :]) ** 2
        r2[~ok] = np.inf
    else:
        ph = np.concatenate([xa, np.ones((k, 1))], axis=1)          # (k, 3)
        A = ph[samples]                                              # (it, 3, 3)
        B = xb[samples]                                              # (it, 3, 2)
        det = np.linalg.det(A)
        ok = np.abs(det) > 1e-3
        M = np.zeros((iterations, 3, 2))
        if ok.any():
            M[ok] = np.linalg.solve(A[ok], B[ok])
        ok &= _affine_ok(np.swapaxes(M[:, :2], 1, 2), scale_range, max_anisotropy)
        pred = np.einsum("kc,icd->ikd", ph, M)                       # (it, k, 2)
        r2 = np.sum((pred - xb[None]) ** 2, axis=2)
        r2[~ok] = np.inf
    inl = r2 < thr2
    score = inl @ w
    best = int(np.argmax(score))
    mask = inl[best]
    if mask.sum() < need:
        return none
    # one weighted least-squares refinement on the inliers, then re-count
    if model is GeometryModel.SIMILARITY:
        a_r, b_r = _fit_similarity(xa[mask], xb[mask], w[mask])
        predict = _apply_similarity(a_r, b_r)
        plausible = scale_range[0] <= abs(a_r) <= scale_range[1]
    else:
        ph = np.concatenate([xa, np.ones((k, 1))], axis=1)
        sw = np.sqrt(np.maximum(w[mask], 1e-12))[:, None]
        M, *_ = np.linalg.lstsq(ph[mask] * sw, xb[mask] * sw, rcond=None)
        predict = _apply_affine(M)
        plausible = bool(_affine_ok(M[:2].T, scale_range, max_anisotropy))
    refined = np.sum((predict(xa) - xb) ** 2, axis=1) < thr2
    if plausible and refined @ w >= mask @ w:
        return refined, predict
    if model is GeometryModel.SIMILARITY:
        j = samples[best]
        a0 = (xb[j[1], 0] - xb[j[0], 0] + 1j * (xb[j[1], 1] - xb[j[0], 1])) / \
             (xa[j[1], 0] - xa[j[0], 0] + 1j * (xa[j[1], 1] - xa[j[0], 1]))
        return mask, _apply_similarity(a0, (xb[j[0], 0] + 1j * xb[j[0], 1]) - a0 * (xa[j[0], 0] + 1j * xa[j[0], 1]))
    return mask, _apply_affine(M_best(xa, xb, samples[best]))


def M_best(xa: np.ndarray, xb: np.ndarray, j: np.ndarray) -> np.ndarray:
    """The affine transform through three correspondences."""
    ph = np.concatenate([xa[j], np.ones((3, 1))], axis=1)
    return np.linalg.solve(ph, xb[j])


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


def transform_overlap(predict: Callable[[np.ndarray], np.ndarray], size_a: tuple[int, int],
                      size_b: tuple[int, int]) -> float:
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
