"""Landmark recognition between two horizons (paper §3.1): nearest-neighbour matching with a ratio test, the
recognition score (sum of inverse descriptor distances), and "NN with RANSAC" fitting the line
x_test = b_s * x_stored + b_d, which also tells how the robot moved (b_d: a turn, b_s: moving closer or away).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from loops.horizon.params import Consensus, HorizonParams
from loops.horizon.surf1d import SIGN_WEIGHT, HorizonFeatures
from odometry.shared.ransac import all_pairs, find_consensus, refit_if_not_worse, sample_pairs


@dataclass(frozen=True)
class MatchResult:
    """Outcome of matching a test horizon against a stored one.

    score: NN recognition score, sum over ratio-test matches of 1 / descriptor distance.
    score_ransac: the same sum over the RANSAC consensus set (0 when fewer than ransac_min_inliers agree).
    b_s, b_d: the fitted x_test = b_s * x_stored + b_d (image pixels); NaN when RANSAC found no consensus.
    matches: (M, 2) indices (test feature, stored feature) passing the ratio test.
    distances: (M,) their descriptor distances.
    inliers: (M,) bool, the consensus set.
    """

    score: float
    score_ransac: float
    b_s: float
    b_d: float
    matches: np.ndarray
    distances: np.ndarray
    inliers: np.ndarray

    @property
    def n_matches(self) -> int:
        return int(self.matches.shape[0])

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())


def _no_match(matches: np.ndarray, dist: np.ndarray, score: float) -> MatchResult:
    return MatchResult(score, 0.0, float("nan"), float("nan"), matches, dist, np.zeros(len(dist), bool))


def nn_matches(test: HorizonFeatures, stored: HorizonFeatures, params: HorizonParams = HorizonParams()
               ) -> tuple[np.ndarray, np.ndarray]:
    """Nearest stored neighbour of every test feature passing the ratio test: ((M, 2) index pairs, (M,) distances).

    With params.match_sign, features only match features of the same blob sign (the nearest and second-nearest
    are sought among those); with params.one_to_one, a stored feature keeps only its closest test feature.
    """
    n = len(test)
    if n == 0 or len(stored) < 2:
        return np.zeros((0, 2), np.intp), np.zeros(0)
    ka, _ = test.keys
    _, kbt = stored.keys
    if params.match_sign:
        sim = ka @ kbt                       # desc . desc + SIGN_WEIGHT^2 * sign * sign
        base = 2.0 + 2.0 * SIGN_WEIGHT ** 2  # |a - b|^2 = base - 2 sim
    else:
        sim = ka[:, :-1] @ kbt[:-1]
        base = 2.0
    rows = np.arange(n)
    j1 = sim.argmax(axis=1)
    s1 = sim[rows, j1]
    sim[rows, j1] = -np.inf
    s2 = sim[rows, sim.argmax(axis=1)]
    d1 = base - 2.0 * s1
    ok = d1 < (params.ratio ** 2) * (base - 2.0 * s2)
    if params.match_sign:
        ok &= s1 > 0.0                       # the nearest has the same sign (else sim <= 1 - SIGN_WEIGHT^2 < 0)
    ti = np.flatnonzero(ok)
    si = j1[ti]
    dist = np.sqrt(np.maximum(d1[ti], 0.0))
    if params.one_to_one and ti.size > 1:
        order = np.lexsort((dist, si))
        first = np.ones(order.size, bool)
        first[1:] = si[order][1:] != si[order][:-1]
        keep = np.sort(order[first])
        ti, si, dist = ti[keep], si[keep], dist[keep]
    return np.stack([ti, si], axis=1), dist.astype(np.float64)


@functools.lru_cache(maxsize=512)
def _hypotheses(m: int, iterations: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j), i != j, for RANSAC on m matches: all pairs when few, else `iterations` random ones.

    Cached per (m, iterations, seed), so RANSAC is deterministic and needs no random generator per call.
    """
    if m * (m - 1) // 2 <= iterations:
        i, j = all_pairs(m)
    else:
        i, j = sample_pairs(np.random.default_rng([seed, m]), m, iterations, cyclic=True)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j


def _lines(x_test: np.ndarray, x_stored: np.ndarray, pairs: tuple[np.ndarray, np.ndarray], lo: float,
           hi: float) -> tuple[np.ndarray, np.ndarray]:
    """(b_s, b_d) of the line through each pair of matches; b_s is NaN where undefined or outside [lo, hi]."""
    i, j = pairs
    xs_i = x_stored[i]
    xt_i = x_test[i]
    dxs = xs_i - x_stored[j]
    dxs[dxs == 0] = np.nan                   # two matches on one stored column define no line
    bs = (xt_i - x_test[j]) / dxs
    bs[~((bs >= lo) & (bs <= hi))] = np.nan  # NaN fails every inlier test below
    return bs, xt_i - bs * xs_i


def _line_inliers(lines: tuple[np.ndarray, np.ndarray], x_test: np.ndarray, x_stored: np.ndarray,
                  params: HorizonParams, log_scale_ratio: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Inlier counts and the (lines x matches) 0/1 inlier matrix. Residuals are computed in place in float32
    (pixels: ample precision); the indicator stays 0/1 float so that counting is a matrix-vector product."""
    bs, bd = lines
    res = np.multiply.outer(bs.astype(np.float32), x_stored.astype(np.float32))
    res += bd.astype(np.float32)[:, None]
    res -= x_test.astype(np.float32)
    np.abs(res, out=res)
    inl = np.less_equal(res, np.float32(params.ransac_tolerance), out=res)
    if log_scale_ratio is not None:
        inl *= np.abs(log_scale_ratio - np.log2(bs)[:, None]) <= params.scale_tolerance
    return inl @ np.ones(len(x_test), np.float32), inl


def _refit_line(inliers: np.ndarray, x_test: np.ndarray, x_stored: np.ndarray, params: HorizonParams,
                log_scale_ratio: np.ndarray | None) -> tuple[tuple[float, float], np.ndarray] | None:
    """Least-squares line through the consensus set and its inliers (None when degenerate or implausible)."""
    xs, xt = x_stored[inliers], x_test[inliers]
    xm, tm = xs.mean(), xt.mean()
    dx = xs - xm
    var = float(dx @ dx)
    if var <= 0:
        return None
    rs = float(dx @ (xt - tm)) / var
    if not 1.0 / params.max_scale_change <= rs <= params.max_scale_change:
        return None
    rd = tm - rs * xm
    mask = np.abs(x_test - (rs * x_stored + rd)) <= params.ransac_tolerance
    if log_scale_ratio is not None:
        mask &= np.abs(log_scale_ratio - np.log2(rs)) <= params.scale_tolerance
    return (rs, rd), mask


def fit_line_ransac(x_test: np.ndarray, x_stored: np.ndarray, params: HorizonParams = HorizonParams(),
                    log_scale_ratio: np.ndarray | None = None) -> tuple[float, float, np.ndarray]:
    """RANSAC fit of x_test = b_s * x_stored + b_d: (b_s, b_d, inlier mask), or (nan, nan, all False) when no line
    gathers params.ransac_min_inliers. Lines with b_s outside [1/max_scale_change, max_scale_change] are not
    considered (b_s <= 0 would reverse the horizon's order).

    With params.scale_tolerance > 0 and log_scale_ratio = log2(test scale / stored scale) per match, an inlier's
    scale ratio must also agree with b_s within that many octaves. The largest consensus set wins (the first
    hypothesis on ties); the line is then refitted to it by least squares, kept if it does not lose inliers.
    """
    m = x_test.shape[0]
    none = (float("nan"), float("nan"), np.zeros(m, bool))
    if m < max(2, params.ransac_min_inliers):
        return none
    lo, hi = 1.0 / params.max_scale_change, params.max_scale_change
    lsr = log_scale_ratio if params.scale_tolerance > 0 else None
    best = find_consensus(lambda _: _lines(x_test, x_stored, _hypotheses(m, params.ransac_iterations, params.seed),
                                           lo, hi),
                          lambda lines: _line_inliers(lines, x_test, x_stored, params, lsr), params.ransac_iterations)
    if best is None or best.score < params.ransac_min_inliers:
        return none
    mask = best.inliers > 0
    refined = refit_if_not_worse(mask, lambda inl: _refit_line(inl, x_test, x_stored, params, lsr), np.count_nonzero)
    if refined is not None:
        (rs, rd), mask2 = refined
        return rs, rd, mask2
    bs, bd = best.hypotheses
    return float(bs[best.index]), float(bd[best.index]), mask


def match(test: HorizonFeatures, stored: HorizonFeatures, params: HorizonParams = HorizonParams()) -> MatchResult:
    """Match a test horizon against a stored one: NN score, NN+RANSAC score and the fitted (b_s, b_d)."""
    pairs, dist = nn_matches(test, stored, params)
    w = 1.0 / np.maximum(dist, params.min_distance)
    score = float(w.sum())
    if pairs.shape[0] < params.ransac_min_inliers:
        return _no_match(pairs, dist, score)
    ti, si = pairs[:, 0], pairs[:, 1]
    if params.consensus is Consensus.SHIFT:
        s_score, b_d, inl = shift_consensus(test.x[ti] - stored.x[si], w, params)
        return MatchResult(score, s_score, 1.0 if inl.any() else float("nan"), b_d, pairs, dist, inl)
    lsr = np.log2(test.scale[ti] / stored.scale[si]) if params.scale_tolerance > 0 else None
    b_s, b_d, inl = fit_line_ransac(test.x[ti], stored.x[si], params, lsr)
    return MatchResult(score, float(w[inl].sum()), b_s, b_d, pairs, dist, inl)


def shift_bins(shift: np.ndarray, params: HorizonParams) -> np.ndarray:
    """Histogram bin of each shift x_test - x_stored (pixels): bins ransac_tolerance px wide, anchored at 0."""
    return np.floor(shift / params.ransac_tolerance).astype(np.intp)


def shift_consensus(shift: np.ndarray, weights: np.ndarray, params: HorizonParams
                    ) -> tuple[float, float, np.ndarray]:
    """Consensus.SHIFT: the heaviest window of two adjacent bins (2 * ransac_tolerance px) of the match shifts.

    A window holding fewer than ransac_min_inliers matches scores 0. Returns (its weight sum, the mean shift of its
    matches = b_d with b_s = 1, its matches as a mask); (0, NaN, none) when no window qualifies. Any cluster of
    shifts at most ransac_tolerance wide falls inside one window, as the RANSAC line's inliers lie within
    ransac_tolerance of the line; what is lost is b_s (moving closer or away), which a long horizon needs and a
    turn does not.
    """
    m = shift.shape[0]
    none = (0.0, float("nan"), np.zeros(m, bool))
    if m < params.ransac_min_inliers:
        return none
    b = shift_bins(shift, params)
    b -= b.min()
    n_bins = int(b.max()) + 2
    h = np.bincount(b, weights=weights, minlength=n_bins)
    c = np.bincount(b, minlength=n_bins)
    hw = h[:-1] + h[1:]
    hw[(c[:-1] + c[1:]) < params.ransac_min_inliers] = 0.0
    k = int(np.argmax(hw))
    if hw[k] <= 0:
        return none
    inl = (b == k) | (b == k + 1)
    return float(hw[k]), float(shift[inl].mean()), inl
