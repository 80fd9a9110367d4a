"""Inlier tests for loop closures: chi-square thresholds, the loop-probability shift, the residual scale."""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from graph.params import GraphParams, LoopWeighting


def base_threshold(dof: int, params: GraphParams) -> float:
    """Squared Mahalanobis residual below which a loop is an inlier: the chi-square quantile."""
    return float(chi2.ppf(params.robust.inlier_probability, dof))


def loop_thresholds(probability: np.ndarray, dof: int, params: GraphParams) -> np.ndarray:
    """Per-loop thresholds on r^2; with THRESHOLD weighting shifted by 2 * logit(p).

    The shift is the log-odds term of a Bayesian inlier test (Gaussian inlier against a flat outlier density): a
    loop the loop model calls likely gets a looser test, an unlikely one a stricter test. p = 0.5 and an unknown p
    (NaN) leave the quantile unchanged.
    """
    p = np.asarray(probability, float).reshape(-1)
    base = base_threshold(dof, params)
    c2 = np.full(len(p), base)
    if params.robust.loop_weighting == LoopWeighting.THRESHOLD and len(p):
        known = np.isfinite(p)
        pc = np.clip(p[known], params.robust.probability_clip, 1.0 - params.robust.probability_clip)
        c2[known] = np.maximum(base + 2.0 * np.log(pc / (1.0 - pc)), 0.05 * base)
    return c2


def information_scale(probability: np.ndarray, params: GraphParams) -> np.ndarray | None:
    """Factor on each loop's information with INFORMATION weighting (p; 1 where unknown), else None."""
    if params.robust.loop_weighting != LoopWeighting.INFORMATION:
        return None
    p = np.asarray(probability, float).reshape(-1)
    return np.where(np.isfinite(p), np.clip(p, params.robust.probability_clip, 1.0), 1.0)


def fence_scale(r2_inliers: np.ndarray, dof: int, factor: float, quantile: float = 0.9, floor: float = 1e-6,
                min_loops: int = 20) -> float:
    """How much to tighten the stated-information thresholds, from the residuals of accepted loops.

    scale = factor * quantile_q(r^2) / chi-square_q(dof), clipped to [floor, 1]: a loop is an inlier if its residual
    is within `factor` times the q-quantile of its peers', and never looser than the stated information allows.
    Public graphs state information 10-1000x looser than their residuals (w10000's unit information against
    residuals of a few centimetres), so under the stated model a false loop between nearby places fits; residual
    tails of real graphs are heavier than chi-square, hence a high quantile and a generous factor rather than the
    median. With data that matches its stated noise the scale is 1 (no change). Fewer than `min_loops`: 1.
    """
    r2 = np.asarray(r2_inliers, float)
    if len(r2) < min_loops:
        return 1.0
    return float(np.clip(factor * np.quantile(r2, quantile) / chi2.ppf(quantile, dof), floor, 1.0))


def short_span(span: np.ndarray, window: int) -> np.ndarray:
    """Loops whose ends are at most 2 x `window` odometry steps apart: the longest cycle the local consistency test
    (graph.support, both ends within `window` nodes) closes, so over such a span the variance factor measured on the
    agreeing cycles describes the loop's own residual, and no map-scale strain (a long drift a lone loop closes)
    excuses a misfit."""
    return np.asarray(span) <= 2 * max(int(window), 0)


def tail_margin(r2_kept: np.ndarray, sigma0: float, dof: int, params: GraphParams) -> float:
    """Acceptance margin (x the variance factor) from the tail of the kept loops' residuals at a solution, such that
    a loop is accepted within `fence_factor` x their `fence_quantile` of r^2 (the fence of `fence_scale`): that
    r^2 over sigma0 x the chi-square quantile of the inlier test (`inlier_probability`), clipped to
    [1, calibration_margin]. The global margin (`calibration_margin`) is set against the median of the agreeing
    cycles, so it must also cover their heavy tail; the kept loops' own high quantile measures that tail, and the
    same factor above it is room enough. Never looser than the global margin, never tighter than the calibrated
    quantile itself. Fewer than `calibration_min_loops` kept loops: the global margin."""
    r2 = np.asarray(r2_kept, float)
    margin = params.robust.calibration_margin
    if len(r2) < params.robust.calibration_min_loops or sigma0 <= 0:
        return margin
    fence = params.robust.fence_factor * float(np.quantile(r2, params.robust.fence_quantile))
    m = fence / (sigma0 * base_threshold(dof, params))
    return float(np.clip(m, 1.0, max(margin, 1.0)))


def family_bound(n: int, dof: int, probability: float) -> float:
    """chi-square_dof^-1(1 - (1 - probability) / n): the Bonferroni bound of n tests at family-wise level
    1 - probability (each of n true loops of the calibrated model exceeds it with probability at most
    (1 - probability) / n; the short-tail screen's `screen_family_bound`)."""
    return float(chi2.ppf(1.0 - (1.0 - probability) / max(int(n), 1), dof))


def heavy_tailed(r2_units: np.ndarray, dof: int, probability: float) -> bool:
    """More than a share 1 - probability of `r2_units` (squared residuals in units of the variance factor) above the
    chi-square `probability` quantile: the residuals are heavier-tailed than the calibrated model (intel clean:
    2.8 %), and a bound that assumes the model does not apply."""
    r2 = np.asarray(r2_units, float)
    return bool(len(r2)) and float(np.mean(r2 > chi2.ppf(probability, dof))) > 1.0 - probability
