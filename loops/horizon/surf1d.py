"""1D SURF: box-filter second derivatives over a 1D integral signal, extrema in space, 6-number descriptors.

Everything runs on whole arrays, all scales at once: one integral signal; every box-filter response at every
(level, position) candidate from one gather and one small matrix product; extrema by array comparisons; all
descriptors from one gather and two matrix products. The index tables depend only on the signal length and the
parameters, so they are built once and cached (a robot's horizon has the same length every frame).

Differences from 2D SURF, as in the paper: the "Hessian" is the second derivative alone; extrema are sought in
space only (each scale level on its own, no 3x3x3 test); no orientation; no sub-sample interpolation.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from loops.horizon.params import HorizonParams, SampleMode
from loops.horizon.signal import HorizonError, HorizonLine, horizon_signal, sample_columns

SIGN_WEIGHT = 2.0  # sign column of the matching keys: opposite-sign pairs get 4 * 2^2 = 16 added to |a - b|^2


@dataclass(frozen=True)
class HorizonFeatures:
    """1D SURF features of one horizon. Arrays share their first dimension (one row per feature).

    x: image column of the feature (pixels; samples sit every params.step columns).
    scale: the feature scale s in image pixels (0.4 x the box-filter lobe, as SURF's 1.2 L / 9).
    level: index into the scale ladder (`scale_levels`).
    sign: +1 for a dark blob (positive second derivative), -1 for a bright one.
    response: scale-normalised second-derivative response, grey levels per band pixel.
    descriptor: (N, 2 * subregions) float32, unit length.
    width: number of image columns the horizon spans.
    """

    x: np.ndarray
    scale: np.ndarray
    level: np.ndarray
    sign: np.ndarray
    response: np.ndarray
    descriptor: np.ndarray
    width: int

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @classmethod
    def empty(cls, width: int = 0, dim: int = 6) -> "HorizonFeatures":
        return cls(np.zeros(0), np.zeros(0), np.zeros(0, np.intp), np.zeros(0, np.int8), np.zeros(0),
                   np.zeros((0, dim), np.float32), int(width))

    @functools.cached_property
    def keys(self) -> tuple[np.ndarray, np.ndarray]:
        """Matching keys: descriptor plus a sign column, as (N, D+1) and its contiguous transpose (D+1, N).

        With unit descriptors, key_a . key_b = desc_a . desc_b + SIGN_WEIGHT^2 * sign_a * sign_b, so one matrix
        product gives descriptor distances and the sign-of-Laplacian test together. Computed once per feature set.
        """
        k = np.empty((len(self), self.descriptor.shape[1] + 1), np.float32)
        k[:, :-1] = self.descriptor
        k[:, -1] = self.sign * SIGN_WEIGHT
        return k, np.ascontiguousarray(k.T)


@dataclass(frozen=True)
class ScaleLevel:
    octave: int
    interval: int
    lobe: int     # samples per lobe; the (+1, -2, +1) filter is 3 * lobe samples long
    stride: int   # sampling step of the octave (2^octave samples)


@functools.lru_cache(maxsize=32)
def scale_levels(params: HorizonParams) -> tuple[ScaleLevel, ...]:
    """The scale ladder: SURF's lobes L/3 = 2^(o+1) (i+1) + 1 for octaves o and intervals i, octave o sampled every
    2^o samples. A filter that repeats one of a finer octave (lobes 5, 9, 17 with 3 intervals) is skipped: in a
    space-only search its features would be exact duplicates, and duplicates make the ratio test reject the true
    match. With 4 octaves x 3 intervals this leaves 9 levels: lobes 3, 5, 7, 9, 13, 17, 25, 33, 49.
    """
    out, seen = [], set()
    for o in range(params.octaves):
        for i in range(params.intervals):
            lobe = 2 ** (o + 1) * (i + 1) + 1
            if lobe not in seen:
                seen.add(lobe)
                out.append(ScaleLevel(o, i, lobe, 2 ** o))
    return tuple(out)


def lobe_sizes(params: HorizonParams) -> np.ndarray:
    """Lobe length (samples) of each scale level, finest first."""
    return np.array([lv.lobe for lv in scale_levels(params)], dtype=np.intp)


def min_signal_length(params: HorizonParams) -> int:
    """Shortest signal with at least three positions for the smallest filter (an extremum needs neighbours)."""
    return 3 * int(lobe_sizes(params)[0]) + 2


@dataclass(frozen=True)
class SignalPlan:
    """Index tables for one (signal length, params): built once, reused for every horizon of that length.

    Candidates are the positions each level is evaluated at: every sample in octave 0, every 2^o-th in octave o
    (SURF's doubling sampling step), concatenated level after level into one flat vector.
    """

    n: int
    min_length: int
    pad: int
    cand_level: np.ndarray    # (M,) level of each candidate
    cand_pos: np.ndarray      # (M,) sample position of each candidate
    resp_idx: np.ndarray      # (4, M) indices into the padded integral signal
    resp_weight: np.ndarray   # (M,) 1 / (lobe * pixels per sample), 0 where a filter does not fit
    desc_idx: np.ndarray      # (M, S + 2) integral look-ups of each candidate's descriptor samples
    desc_haar: np.ndarray     # (S + 2, S + D): look-ups -> [Haar responses dx | per-subregion weighted sum dx]
    desc_abs: np.ndarray      # (S, D) Gaussian weights summing |dx| into each subregion's sum |dx|
    scale_px: np.ndarray      # (K,) feature scale in image pixels
    columns: np.ndarray       # (n,) image column of each sample


@functools.lru_cache(maxsize=32)
def signal_plan(n: int, params: HorizonParams) -> SignalPlan:
    lobes = lobe_sizes(params)
    half = (lobes - 1) // 2
    s = 0.4 * lobes  # SURF: s = 1.2 * L / 9 with L = 3 * lobe
    n_sub, per_sub = params.subregions, params.samples_per_subregion
    n_samples = n_sub * per_sub
    # Descriptor samples every q samples (q ~ descriptor_window * s / n_samples, i.e. s by default) with Haar
    # wavelets of size 2q, as SURF (samples every s, wavelets of size 2s). On this regular grid neighbouring
    # samples share integral look-ups: n_samples + 2 look-ups per feature instead of 3 n_samples.
    q = np.maximum(1, np.rint(params.descriptor_window * s / n_samples)).astype(np.intp)   # (K,)
    grid = np.arange(-1, n_samples + 1) - (n_samples - 1) // 2                                 # (S + 2,)
    offsets = grid[None, :] * q[:, None]                                                       # (K, S + 2)
    reach_desc = int(np.abs(offsets).max()) + 1
    reach_filter = int((half + lobes).max()) + 1
    pad = max(reach_desc, reach_filter)

    levels, positions = [], []
    for k, lv in enumerate(scale_levels(params)):
        pos = np.arange(0, n, lv.stride)
        levels.append(np.full(pos.size, k))
        positions.append(pos)
    cand_level = np.concatenate(levels)
    cand_pos = np.concatenate(positions)
    h, lo = half[cand_level], lobes[cand_level]
    p = cand_pos + pad
    # (+1, -2, +1) lobes = full span - 3 x centre lobe: I[full end] - I[full start] - 3 (I[centre end] - I[start]).
    resp_idx = np.stack([p + h + lo + 1, p - h - lo, p + h + 1, p - h])
    # A filter that does not fit gives 0; each level's first and last candidates never fit, so comparing
    # neighbours in the flat vector never mixes two levels.
    fits = (cand_pos - h - lo >= 0) & (cand_pos + h + lo <= n - 1)
    # Per-pixel grey levels whatever the band: divide by the pixels summed into each sample.
    pixels = params.band_height * (params.step if params.sample_mode is SampleMode.BOX else 1)
    resp_weight = np.where(fits, 1.0 / (lo * pixels), 0.0)
    desc_idx = offsets[cand_level] + p[:, None]                                     # (M, S + 2)
    # Haar response at sample j: I[o_j + q] - 2 I[o_j] + I[o_j - q] = sum[o_j, o_j + q) - sum[o_j - q, o_j).
    haar_mat = np.zeros((n_samples + 2, n_samples))
    j = np.arange(n_samples)
    haar_mat[j, j], haar_mat[j + 1, j], haar_mat[j + 2, j] = 1.0, -2.0, 1.0
    centred = np.arange(n_samples) - (n_samples - 1) / 2.0
    g = np.exp(-0.5 * (centred * params.descriptor_window / n_samples / params.gaussian_sigma) ** 2)
    sub = j // per_sub
    signed = np.zeros((n_samples, 2 * n_sub))
    signed[j, 2 * sub] = g
    desc_abs = np.zeros((n_samples, 2 * n_sub))
    desc_abs[j, 2 * sub + 1] = g
    desc_haar = np.concatenate([haar_mat, haar_mat @ signed], axis=1)
    columns = sample_columns(n, params)
    tables = (cand_level, cand_pos, resp_idx, resp_weight, desc_idx, desc_haar, desc_abs, columns)
    for a in tables:
        a.setflags(write=False)
    return SignalPlan(n, min_signal_length(params), pad, cand_level, cand_pos, resp_idx, resp_weight, desc_idx,
                 desc_haar, desc_abs, s * params.step, columns)


def responses(signal: np.ndarray, params: HorizonParams = HorizonParams()) -> tuple[np.ndarray, np.ndarray,
                                                                                       np.ndarray]:
    """Scale-normalised box-filter second derivatives at every candidate: (level, position, response) arrays.

    The response is zero where a filter does not fit in the signal.
    """
    signal = np.asarray(signal, dtype=np.float64)
    plan = signal_plan(len(signal), params)
    return plan.cand_level, plan.cand_pos, _responses(_padded_integral(signal, plan.pad), plan)


def _padded_integral(signal: np.ndarray, pad: int) -> np.ndarray:
    # Edge replication beyond the ends: Haar responses there are zero instead of a fake drop to black.
    n = signal.shape[0]
    buf = np.empty(n + 2 * pad + 1)
    buf[0] = 0.0
    buf[1:pad + 1] = signal[0]
    buf[pad + 1:pad + 1 + n] = signal
    buf[pad + 1 + n:] = signal[-1]
    return np.cumsum(buf, out=buf)


RESP_COEF = np.array([1.0, -1.0, -3.0, 3.0])


def _responses(integral: np.ndarray, plan: SignalPlan) -> np.ndarray:
    r = RESP_COEF @ integral[plan.resp_idx]
    r *= plan.resp_weight
    return r


def detect_and_describe(signal: np.ndarray, params: HorizonParams = HorizonParams()) -> HorizonFeatures:
    """1D SURF features of a horizon signal (sample k at image column `sample_columns(n, params)[k]`)."""
    signal = np.asarray(signal, dtype=np.float64)
    if signal.ndim != 1:
        raise HorizonError(f"a horizon signal is one-dimensional, got shape {signal.shape}")
    n = signal.shape[0]
    plan = signal_plan(n, params)
    if n < plan.min_length:
        raise HorizonError(
            f"horizon signal too short: {n} samples (image width / step {params.step}); 1D SURF needs at least "
            f"{plan.min_length} so the smallest box filter ({3 * int(lobe_sizes(params)[0])} samples) has room")
    integral = _padded_integral(signal, plan.pad)
    r = _responses(integral, plan)

    # Extrema in space only (paper Fig. 1 right): |r| above threshold and above both neighbours of its level.
    a = np.abs(r)
    c = a[1:-1]
    idx = np.flatnonzero((c > np.maximum(a[:-2], params.threshold)) & (c >= a[2:]))
    idx += 1
    if 0 < params.max_features < idx.size:
        # The strongest by |response| (ties: the first position), kept in position order.
        idx = np.sort(idx[np.argsort(-a[idx], kind="stable")[:params.max_features]])
    if idx.size == 0:
        return HorizonFeatures.empty(n * params.step, 2 * params.subregions)

    # Descriptor: Haar responses (size 2s) at 3 x 5 samples spaced by s; per subregion the Gaussian-weighted
    # sums of dx and |dx| (both matrix products); unit length.
    n_s = plan.desc_abs.shape[0]
    out = integral[plan.desc_idx[idx]] @ plan.desc_haar                     # (N, S + D)
    desc = np.abs(out[:, :n_s]) @ plan.desc_abs
    desc += out[:, n_s:]
    desc /= np.sqrt(np.einsum("ij,ij->i", desc, desc) + 1e-24)[:, None]

    level = plan.cand_level[idx]
    resp = r[idx]
    return HorizonFeatures(
        x=plan.columns[plan.cand_pos[idx]],
        scale=plan.scale_px[level],
        level=level,
        sign=np.sign(resp).astype(np.int8),   # never 0: |resp| > threshold >= 0
        response=resp,
        descriptor=desc.astype(np.float32),
        width=n * params.step,
    )


def extract_features(image: np.ndarray, horizon: float | HorizonLine, params: HorizonParams = HorizonParams()
                     ) -> HorizonFeatures:
    """Horizon signal of `image` along `horizon` (row or HorizonLine), then its 1D SURF features."""
    return detect_and_describe(horizon_signal(image, horizon, params), params)
