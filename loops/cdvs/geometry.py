"""Geometric consistency of tentative matches, first stage: DISTRAT (log-distance-ratio statistics, Lepsoy et al.
2011, as used by MPEG CDVS). The few RANSAC iterations of a similarity or affine transform that follow it live in
`loops.geometry`.

DISTRAT needs no model of the transform: for inlier pairs the log ratio of distances between two matched
points in image A and in image B is nearly constant (the log scale change); for outliers it follows the
distribution of the difference of two independent log distances, which is estimated from the two point sets
themselves. A chi-square goodness-of-fit test says whether any inliers are present; the principal eigenvector of
the histogram excess (observed - scaled outlier model) over the pairs picks them.
"""
from __future__ import annotations

import functools

import numpy as np

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
