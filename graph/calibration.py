"""Noise calibration from the agreeing cycles (graph.support): how far the stated covariances are off.

Public graphs state their noise 10-1000x too loose, the pipeline's loop poses ~2x too tight; the robust solve's
loop thresholds are scaled by the variance factor of the short cycles whose loops agree (local, so neither drift
nor a false loop bending the map enters it). One scalar factor (`scalar_factor`: the cycles' median squared
Mahalanobis error over the chi-square median) assumes the stated rotation and translation noise are off by the same
factor. 3D graphs often are not (sphere2500 states its rotation noise looser than its translation noise, and its
rotation noise moves the cycle's translation by the lever arm; parking-garage the other way round), and one factor
then loosens every threshold too far (local false loops fit) or tightens it (true loops rejected).

`split_factors` estimates two: s_r from the rotation part of the cycle errors alone (whitened by the rotation
block of the cycle covariance: its median squared error over the chi-square median of 3 dof), then s_t so that
the translation part's squared error conditioned on the rotation part (whitened by the covariance with its
translation block scaled by s_t and its rotation block by s_r) has the chi-square median of 3 dof: a 1-D root
search. `scale_information` applies them to every edge's information, so the solve tests each loop on the
calibrated model (thresholds then carry no variance factor)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from scipy.stats import chi2

from graph.model import PoseGraphData
from graph.support import CycleSupport


@dataclass(frozen=True)
class VarianceFactors:
    """Variance factors of the stated noise (calibrated covariance = factor x stated), translation and rotation
    blocks (3D), and the single factor of the whole error (what one scalar calibration would use)."""

    translation: float
    rotation: float
    scalar: float

    @property
    def split(self) -> bool:
        return self.translation != self.rotation


def scalar_factor(cycles: CycleSupport, dof: int) -> float:
    """The median squared Mahalanobis error of the agreeing cycles over the chi-square median of `dof`."""
    return float(np.median(cycles.r2)) / float(chi2.ppf(0.5, dof))


def refined_factor(cycles: CycleSupport, dof: int, bound: float, rounds: int) -> float:
    """`scalar_factor`, then re-estimated from the cycles with r^2 <= `bound` x the factor (those that agree on the
    calibrated model, not only on the stated one) until it moves by < 1 % or after `rounds` rounds. The median is
    robust to a minority of cycles through false loops, not to the near-half a loosely stated graph lets agree."""
    s0 = scalar_factor(cycles, dof)
    for _ in range(rounds):
        r2 = cycles.r2[cycles.r2 <= bound * s0]
        if not len(r2):
            break
        s1 = float(np.median(r2)) / float(chi2.ppf(0.5, dof))
        done = abs(s1 - s0) <= 0.01 * s0
        s0 = s1
        if done:
            break
    return s0


def _quadratic_parts(e: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per cycle: the terms of e^T D^-1 S^-1 D^-1 e with D = diag(sqrt(s_t) I, sqrt(s_r) I) as
    a / s_t + 2 b / sqrt(s_t s_r) + c / s_r, and the rotation part's own squared error e_r^T S_rr^-1 e_r."""
    info = np.linalg.inv(s)
    et, er = e[:, :3], e[:, 3:]
    a = np.einsum("ni,nij,nj->n", et, info[:, :3, :3], et)
    b = np.einsum("ni,nij,nj->n", et, info[:, :3, 3:], er)
    c = np.einsum("ni,nij,nj->n", er, info[:, 3:, 3:], er)
    rot = np.einsum("ni,ni->n", er, np.linalg.solve(s[:, 3:, 3:], er[..., None])[..., 0])
    return a, b, c, rot


def _root_log_factor(excess, guess: float, xtol: float) -> float | None:
    """exp of the root of `excess` (decreasing in the log factor) bracketed outwards from `guess` in steps of
    e^2; None when no sign change is found within e^+-40 of it."""
    lo, hi = guess - 2.0, guess + 2.0
    for _ in range(20):
        if excess(lo) > 0 > excess(hi):
            break
        lo, hi = lo - 2.0, hi + 2.0
    else:
        return None
    return float(np.exp(brentq(excess, lo, hi, xtol=xtol)))


def split_factors(cycles: CycleSupport) -> VarianceFactors | None:
    """Rotation and translation variance factors of 3D cycles (see the module doc); None when the rotation part
    carries no error (a noiseless graph: nothing to split). With the cycle covariances decomposed by the source of
    the noise (`CycleSupport.from_translation`, `from_rotation`), the scaled cycle covariance is
    s_t S_T + s_r S_R (the lever arm of the rotation noise scales with s_r); else the blocks of the summed one."""
    if cycles.from_translation is not None and cycles.from_rotation is not None:
        return _split_propagated(cycles)
    med3 = float(chi2.ppf(0.5, 3))
    a, b, c, rot = _quadratic_parts(np.asarray(cycles.errors, float), np.asarray(cycles.covariances, float))
    s_r = float(np.median(rot)) / med3
    if not np.isfinite(s_r) or s_r <= 0.0:
        return None

    def excess(log_st: float) -> float:
        # translation given rotation: the full squared error minus the rotation part's own, on the scaled model
        st = np.exp(log_st)
        cond = a / st + 2.0 * b / np.sqrt(st * s_r) + c / s_r - rot / s_r
        return float(np.median(cond)) - med3

    # the marginal estimate (exact when the cycle covariances have no translation-rotation cross terms) centres
    # the bracket of the root search; the conditional part falls as s_t grows
    marginal = float(np.median(a)) / med3
    guess = np.log(marginal) if np.isfinite(marginal) and marginal > 0 else np.log(s_r)
    s_t = _root_log_factor(excess, guess, 1e-10)
    return None if s_t is None else VarianceFactors(s_t, s_r, scalar_factor(cycles, 6))


def _split_propagated(cycles: CycleSupport) -> VarianceFactors | None:
    med3 = float(chi2.ppf(0.5, 3))
    e = np.asarray(cycles.errors, float)[cycles.decomposed]
    s_t_part, s_r_part = np.asarray(cycles.from_translation, float), np.asarray(cycles.from_rotation, float)
    er = e[:, 3:]
    # the rotation error of a cycle comes from rotation noise alone
    rot = np.einsum("ni,ni->n", er, np.linalg.solve(s_r_part[:, 3:, 3:], er[..., None])[..., 0])
    s_r = float(np.median(rot)) / med3
    if not np.isfinite(s_r) or s_r <= 0.0:
        return None

    def excess(log_st: float) -> float:
        s = np.exp(log_st) * s_t_part + s_r * s_r_part
        full = np.einsum("ni,ni->n", e, np.linalg.solve(s, e[..., None])[..., 0])
        return float(np.median(full - rot / s_r)) - med3

    # bracket from the translation block of the rotation-free part (its value without lever arms)
    et = e[:, :3]
    marginal = float(np.median(np.einsum("ni,ni->n", et, np.linalg.solve(s_t_part[:, :3, :3], et[..., None])[..., 0])))
    guess = np.log(marginal / med3) if marginal > 0 else np.log(s_r)
    s_t = _root_log_factor(excess, guess, 1e-6)
    return None if s_t is None else VarianceFactors(s_t, s_r, scalar_factor(cycles, 6))


def scale_information(data: PoseGraphData, factors: VarianceFactors) -> PoseGraphData:
    """A copy of a 3D graph whose every edge's information is that of the calibrated covariance
    diag(s_t, s_t, s_t, s_r, s_r, s_r)^(1/2) S diag(...)^(1/2) (file order: translation, rotation)."""
    w = 1.0 / np.sqrt(np.r_[np.full(3, factors.translation), np.full(3, factors.rotation)])
    out = data.copy()
    out.information = data.information * w[None, :, None] * w[None, None, :]
    return out
