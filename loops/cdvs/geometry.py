"""Geometric consistency of tentative matches: DISTRAT (log-distance-ratio statistics, Lepsoy et al. 2011, as
used by MPEG CDVS) followed by a few deterministic RANSAC iterations of a similarity or affine transform.

DISTRAT needs no model of the transform: for inlier pairs the log ratio of distances between two matched
points in image A and in image B is nearly constant (the log scale change); for outliers it follows the
distribution of the difference of two independent log distances, which is estimated from the two point sets
themselves. A chi-square goodness-of-fit test says whether any inliers are present; the principal eigenvector of
the histogram excess (observed - scaled outlier model) over the pairs picks them.
"""
from __future__ import annotations

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


def distrat_inliers(xa: np.ndarray, xb: np.ndarray, chi2_threshold: float) -> np.ndarray:
    """Indices of the matches (rows of xa, xb: (K, 2)) that DISTRAT finds geometrically consistent."""
    k = len(xa)
    if k < 3:
        return np.zeros(0, dtype=np.int64)
    i, j = np.triu_indices(k, 1)
    da = np.sum((xa[i] - xa[j]) ** 2, axis=1, dtype=np.float64)
    db = np.sum((xb[i] - xb[j]) ** 2, axis=1, dtype=np.float64)
    ldr = 0.5 * np.log((da + 1e-6) / (db + 1e-9))
    # outlier model: distribution of (log dA - log dB) for independent pairs = correlation of the two histograms
    la = np.clip(np.rint(0.5 * np.log(da + 1e-9) / _LOG_STEP), 0, _N_LOGD - 1).astype(np.int64)
    lb = np.clip(np.rint(0.5 * np.log(db + 1e-9) / _LOG_STEP), 0, _N_LOGD - 1).astype(np.int64)
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


def ransac(xa: np.ndarray, xb: np.ndarray, w: np.ndarray, model: GeometryModel, iterations: int,
           threshold: float, seed: int = 0) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray] | None]:
    """(inlier mask, fitted transform xa -> xb or None) after a few vectorised RANSAC iterations, refined once by
    weighted least squares on the inliers. Deterministic for a given input and seed."""
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
        predict = _apply_similarity(*_fit_similarity(xa[mask], xb[mask], w[mask]))
    else:
        ph = np.concatenate([xa, np.ones((k, 1))], axis=1)
        sw = np.sqrt(np.maximum(w[mask], 1e-12))[:, None]
        M, *_ = np.linalg.lstsq(ph[mask] * sw, xb[mask] * sw, rcond=None)
        predict = _apply_affine(M)
    refined = np.sum((predict(xa) - xb) ** 2, axis=1) < thr2
    if refined @ w >= mask @ w:
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
