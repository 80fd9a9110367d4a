"""Multi-band 1D SURF in fixed-size arrays: one image's bands extracted in one pass, one test view matched against
many stored views in one pass (not in the paper).

`extract_bands` + `match_bands` spend most of their time in numpy call overhead: a few dozen small array
operations per band and per pair. Here every band of an image is handled by the same calls, and every stored view
of a query by the same calls, so the cost per band and per pair is the arithmetic alone:

- `extract_packed(image, row, params)` -> `PackedBands`: the `params.bands` bands around `row`, at most
  `params.max_features` features each (the strongest), as (bands, K) arrays padded with invalid slots. Per image:
  done once when a view is stored or queried.
- `stack_packed([...])` -> `PackedSet`: stored views side by side, laid out for one matrix product per band. Per
  stored view: done once when the database is built.
- `match_packed(test, stored_set, params, which=None)` -> scores of the test view against each stored view (or
  the subset `which`). Per pair.

The results are those of `extract_bands` / `match_bands` with the same parameters and `Consensus.SHIFT` (the
tests check it on real frames); the RANSAC line has no batched form here. Requires `params.max_features` > 0.

With numba installed (the extra `fast`) extraction and matching each run as one compiled call
(loops.horizon.packed_jit) on tables built here with the numpy path's; the numpy code below is the fallback and
gives the same features (`compiled=` on each function forces either; VSLAM_NUMBA=0 turns the kernels off).
"""
from __future__ import annotations

import functools
import importlib
import importlib.util
import math
import os
import warnings
from dataclasses import dataclass
from types import ModuleType

import cv2
import numpy as np

from loops.horizon.bands import band_rows
from loops.horizon.matching import shift_bins
from loops.horizon.params import Consensus, HorizonParams, SampleMode
from loops.horizon.signal import HorizonError, HorizonLine, as_gray
from loops.horizon.surf1d import RESP_COEF, SIGN_WEIGHT, min_signal_length, signal_plan


@dataclass(frozen=True)
class PackedBands:
    """1D SURF features of every band of one view, at most K per band (empty slots have valid False).

    x: (B, K) image column of each feature. keys: (B, K, D + 1) float32, the descriptor (unit length) and its sign
    times SIGN_WEIGHT (surf1d's matching keys), all 0 in an empty slot. With unit descriptors and SIGN_WEIGHT 2 a
    same-sign pair has similarity in [3, 5], an opposite-sign pair in [-5, -3] and an empty slot 0: the nearest
    stored feature is the largest similarity, and it is a match only when positive.
    width: image columns.
    """

    x: np.ndarray
    keys: np.ndarray
    valid: np.ndarray
    width: int

    @property
    def counts(self) -> np.ndarray:
        """Features per band."""
        return self.valid.sum(axis=1)

    def __len__(self) -> int:
        """Features over all bands."""
        return int(self.valid.sum())


@dataclass(frozen=True)
class PackedSet:
    """P stored views side by side: keys (B, K, P, D + 1) for the similarity product (slot, then view, along its
    rows), x (B, K, P), enough (B, P): the band holds at least two features (a nearest and a second nearest exist)."""

    keys: np.ndarray
    x: np.ndarray
    enough: np.ndarray

    def __len__(self) -> int:
        return int(self.x.shape[2])


@dataclass(frozen=True)
class PackedScores:
    """Scores of one test view against P stored views: NN and consensus sums over the bands, (P,) each."""

    score: np.ndarray
    score_ransac: np.ndarray
    matches: list["PackedMatch"] | None = None    # with details=True: each view's consensus matches


@dataclass(frozen=True)
class PackedMatch:
    """One (test, stored) pair of the packed path: the scores, the shift line (b_s = 1, b_d = the mean shift of
    the consensus matches; NaN when no band has a consensus) and the consensus matches as image columns."""

    score: float
    score_ransac: float
    b_s: float
    b_d: float
    x_test: np.ndarray      # (M,) column of each consensus match in the test view
    x_stored: np.ndarray    # (M,) and in the stored view
    band: np.ndarray        # (M,) its band

    @property
    def n_inliers(self) -> int:
        return int(self.x_test.shape[0])


# The compiled kernels (loops.horizon.packed_jit, numba: the optional extra `fast`) are loaded on first use, not
# at import: importing numba and loading the first kernel cost about 1.7 s per process, which a process that never
# extracts a packed view should not pay. Without numba (or with a numba that fails to import, or with
# VSLAM_NUMBA=0: a short command on a few hundred frames is quicker without that start-up cost) the numpy code
# below is used; both give the same features.
NUMBA_ENV = "VSLAM_NUMBA"
_JIT: list = []     # [] not tried yet; [module] or [None] once tried


def compiled_kernels() -> ModuleType | None:
    """The compiled kernels module, or None when numba is not installed, does not import, or VSLAM_NUMBA is 0."""
    if not _JIT:
        mod = None
        if os.environ.get(NUMBA_ENV, "").strip() != "0" and importlib.util.find_spec("numba") is not None:
            try:
                mod = importlib.import_module("loops.horizon.packed_jit")
            except (ImportError, RuntimeError) as exc:     # a broken numba; no writable cache directory
                warnings.warn(f"compiled 1D SURF kernels unavailable ({exc}); the numpy code runs instead",
                              RuntimeWarning, stacklevel=3)
                mod = None
        _JIT.append(mod)
    return _JIT[0]


def _use_compiled(compiled: bool | None) -> ModuleType | None:
    if compiled is False:
        return None
    mod = compiled_kernels()
    if mod is None and compiled:
        raise HorizonError(f"the compiled packed path needs numba (pip install 'vslam[fast]') and {NUMBA_ENV} not 0")
    return mod


def uses_packed(params: HorizonParams) -> bool:
    """Whether the landmark memory, the recogniser and `vslam horizon` score through this module with `params`
    (preset `fast` does): a fixed number of slots per band, shift consensus, the sign test, no one-to-one."""
    return (params.max_features > 0 and params.consensus is Consensus.SHIFT and params.match_sign
            and not params.one_to_one)


def level_row(horizon: float | HorizonLine) -> float:
    """The row of a level horizon; the packed path reads bands of whole rows, so a tilted line is refused."""
    if isinstance(horizon, HorizonLine):
        if horizon.row_left != horizon.row_right:
            raise HorizonError(f"horizon line {horizon.row_left:g}:{horizon.row_right:g}: the packed path (preset "
                               "fast) needs a level horizon (one row)")
        horizon = horizon.row_left
    try:
        row = float(horizon)
    except (TypeError, ValueError):
        raise HorizonError(f"horizon row must be a number, got {horizon!r}") from None
    if not math.isfinite(row):
        raise HorizonError(f"horizon row must be finite, got {row}")
    return row


@dataclass(frozen=True)
class _BandPlan:
    """Index tables of one (image size, horizon row, params, image dtype): built once, reused for every frame.

    Candidates: per band, each kept level's positions where its filter fits, levels separated by a zero candidate
    (response 0, descriptor 0, column 0), bands end to end with a separator first and last in each; the last is
    the null candidate of an empty slot. A candidate's neighbours in the flat vector are its level's neighbours
    or a separator, as surf1d's non-fitting candidates.
    Box-filter sums and each band's padded integral (as surf1d's, for the descriptor look-ups) are linear in the
    band's signal: for a short signal one matrix product gives both for every band; a long one (the product grows
    with its square) goes through one integral of all bands and a gather.
    """

    rows: np.ndarray | None     # (B * band_height,) image rows band after band; None when they are one slice
    r0: int                     # first row of that slice
    acc: type                   # dtype the band sums are accumulated in (exact)
    lin: np.ndarray | None      # (n, M + seg + 1) the signal -> [every candidate's box-filter sum | the padded
    #                             integral], integer coefficients (short signals; None: the gather path)
    ext: np.ndarray | None      # (B * seg,) gather path: flat index into the band sums of each padded sample
    resp_flat: np.ndarray | None  # (4, B * M) gather path: integral look-ups of every candidate's box filter
    resp_w: np.ndarray          # (B, M) response weight 1 / (lobe * pixels per sample); 0 for a separator
    desc_t: np.ndarray          # (S + 2 + R, B * M) flat look-ups of each candidate's descriptor samples, then of
    #                             its box-filter sum (lin's output: R = 1; the flat integral: R = 4)
    desc_haar: np.ndarray       # (S + D + 1, S + 2 + R): look-ups -> [Haar responses | weighted sums | box sum]
    desc_abs: np.ndarray        # (D, S + D): [Haar responses, abs'd | weighted sums] -> descriptor
    x: np.ndarray               # (B * M,) image column of each candidate
    code: np.ndarray            # (B * M,) sort-key low bits of flat candidate j: M - 1 - its index in its band
    #                             (0 decodes to M - 1, the band's last separator = the null candidate)
    null: np.ndarray            # (B, 1) b * M + M - 1: flat candidate of sort code 0 in band b
    low: int                    # 2^bits - 1 > M: the low bits of a sort key that carry the code
    m: int                      # candidates per band
    n: int
    jit: "JitPlan"              # the same candidates for the compiled kernels (loops.horizon.packed_jit)


@dataclass(frozen=True)
class JitPlan:
    """Tables of packed_jit.extract_kernel: per band candidate (separators included: weight 0, look-ups 0) its
    look-ups in the band's padded integral (padded as far as the fitting candidates reach, as above: the look-ups'
    coefficients sum to 0, so the values are surf1d's), as contiguous arrays."""

    rows: np.ndarray            # (B * band_height,) int64 image rows, band after band
    geo: np.ndarray             # int64 [n, step, box 0/1, pad, band_height, sort-key low mask, samples per
    #                             subregion]
    resp_look: np.ndarray       # (M, 4) int64
    resp_w: np.ndarray          # (M,)
    desc_look: np.ndarray       # (M, S + 2) int64
    x: np.ndarray               # (M,)
    gauss: np.ndarray           # (S,) Gaussian weight of each descriptor sample, subregion after subregion


# Multiply-adds per band of the dense product above which the gather path is used: the two cost the same between
# 61k (a 240-px frame with preset fast, 480 px with lone) and 106k (320 / 640 px) on our 2-core test machine with
# single-threaded BLAS; a 160-px frame is 25k (fast) / 6k (lone), a 640-px crop 410k / 106k.
DENSE_MAX = 80_000
_LAST: list = [None]    # (params, height, width, row, dtype, plan) of the last call: no params hashing per frame


def _band_plan(height: int, width: int, row: float, params: HorizonParams, dtype: np.dtype) -> _BandPlan:
    last = _LAST[0]
    if last is not None and last[0] is params and last[1:5] == (height, width, row, dtype):
        return last[5]
    plan = _band_plan_cached(height, width, row, params, dtype)
    _LAST[0] = (params, height, width, row, dtype, plan)
    return plan


@functools.lru_cache(maxsize=64)
def _band_plan_cached(height: int, width: int, row: float, params: HorizonParams, dtype: np.dtype) -> _BandPlan:
    n = width // params.step if params.sample_mode is SampleMode.BOX else -(-width // params.step)
    if n < min_signal_length(params):
        raise HorizonError(f"horizon signal too short: {n} samples (image width {width} / step {params.step}); "
                           f"1D SURF needs at least {min_signal_length(params)}")
    band, n_bands = params.band_height, params.bands
    starts = []
    for r in band_rows(row, height, params):
        r0 = int(np.floor(r + 0.5)) - band // 2
        if r0 < 0 or r0 + band > height:
            raise HorizonError(f"horizon row {row:g}: a {band}-pixel band needs rows {r0}..{r0 + band - 1}, but "
                               f"the image has rows 0..{height - 1}")
        starts.append(r0)
    rows = (np.array(starts)[:, None] + np.arange(band)).ravel()
    contiguous = bool(np.all(np.diff(rows) == 1))
    box = params.sample_mode is SampleMode.BOX
    plan = signal_plan(n, params)
    # The candidates whose filter fits (the others have response 0), level after level, each level preceded by
    # a separator and the last followed by one: an extremum test next to a separator compares with 0, as next
    # to surf1d's non-fitting candidates.
    fit = np.flatnonzero(plan.resp_weight > 0)
    level = plan.cand_level[fit]
    first = np.r_[True, level[1:] != level[:-1]]
    slots = np.arange(fit.size) + np.cumsum(first)           # candidate index of each fitting one
    m = fit.size + int(first.sum()) + 1
    # The padding the fitting candidates reach (the 1D plan pads for the largest level). Fewer replicated samples
    # shift every integral value by the same multiple of the first sample; responses and Haar sums are
    # differences with coefficients summing to 0, so they do not change.
    resp_idx, desc_idx = plan.resp_idx[:, fit], plan.desc_idx[fit]
    lo, hi = min(resp_idx.min(), desc_idx.min()), max(resp_idx.max(), desc_idx.max())
    pad = max(plan.pad - int(lo), int(hi) - plan.pad - n, 1)
    seg = n + 2 * pad
    delta = plan.pad - pad
    resp_w = np.zeros(m)
    resp_w[slots] = plan.resp_weight[fit]
    sample_max = (255 if dtype == np.uint8 else np.inf) * band * (params.step if box else 1)
    n_look = desc_idx.shape[1]
    if n * (m + seg + 1) <= DENSE_MAX:
        # Box-filter sums and the padded integral as one matrix on the signal: integral column t is the sum of the
        # padded samples j < t, padded sample j being sample clip(j - pad); RESP_COEF combines a filter's four
        # look-ups. Exact in float32 while every sum stays below 2^24 (integer band sums); else float64.
        onehot = np.zeros((seg, n))
        onehot[np.arange(seg), np.clip(np.arange(seg) - pad, 0, n - 1)] = 1.0
        integ = np.concatenate([np.zeros((n, 1)), np.cumsum(onehot, axis=0).T], axis=1)      # (n, seg + 1)
        resp = np.zeros((n, m))
        resp[:, slots] = np.einsum("k,nkf->nf", RESP_COEF, integ[:, resp_idx - delta])
        lin = np.concatenate([resp, integ], axis=1)
        lin = lin.astype(np.float32 if np.abs(lin).sum(axis=0).max() * sample_max < 2 ** 24 else np.float64)
        acc = np.uint16 if dtype == np.uint8 and sample_max < 2 ** 16 else lin.dtype.type
        ext = resp_flat = None
        # Descriptor look-ups into the flat product, then the candidate's box-filter sum (coefficient 1).
        stride, first = m + seg + 1, m
        sum_look, sum_coef = slots[:, None], np.ones(1)
    else:
        # Long signals: the dense product grows with n^2; the bands' padded signals end to end in one flat vector
        # (band b at b * seg), one cv2.integral over it (each band's integral differs from surf1d's by a constant,
        # which the zero-sum look-ups cancel), every box-filter sum from one gather of four look-ups.
        lin = None
        acc = np.uint16 if dtype == np.uint8 and sample_max < 2 ** 16 else np.float64
        src = np.clip(np.arange(seg) - pad, 0, n - 1) * (1 if box else params.step)
        ext = (np.arange(n_bands)[:, None] * (n if box else width) + src).ravel().astype(np.intp)
        look = np.zeros((4, m), np.intp)
        look[:, slots] = resp_idx - delta
        resp_flat = (look[:, None, :] + (np.arange(n_bands) * seg)[None, :, None]).reshape(4, -1).astype(np.intp)
        stride, first = seg, 0
        sum_look, sum_coef = (resp_idx - delta).T, RESP_COEF
    # Descriptor look-ups; separators (and the null candidate) read flat value 0 every time, which is 0 (the first
    # band's first box-filter sum, or the integral's leading 0): Haar responses, descriptor and box-filter sum 0
    # exactly (the descriptor's coefficients do not sum to exactly 0 in floating point).
    desc = np.zeros((m, n_look + sum_coef.size), np.intp)
    desc[slots, :n_look] = desc_idx - delta + first
    desc[slots, n_look:] = sum_look
    desc_flat = (np.arange(n_bands) * stride)[:, None, None] + desc[None]
    sep = np.ones(m, bool)
    sep[slots] = False
    desc_flat[:, sep] = 0
    desc_flat = desc_flat.reshape(n_bands * m, -1)
    x = np.zeros(m)
    x[slots] = plan.columns[plan.cand_pos[fit]]
    d = plan.desc_abs.shape[1]
    desc_abs = np.concatenate([plan.desc_abs, np.eye(d)])             # |Haar| -> sums |dx|; signed sums as they are
    desc_haar = np.zeros((n_look + sum_coef.size, plan.desc_haar.shape[1] + 1))
    desc_haar[:n_look, :-1] = plan.desc_haar
    desc_haar[n_look:, -1] = sum_coef                                   # the box-filter sum (its sign: the blob's)
    code = m - 1 - np.arange(n_bands * m) % m
    j_resp = np.zeros((m, 4), np.int64)
    j_resp[slots] = plan.resp_idx[:, fit].T - delta
    j_desc = np.zeros((m, n_look), np.int64)
    j_desc[slots] = plan.desc_idx[fit] - delta
    low = (1 << m.bit_length()) - 1
    jit = JitPlan(rows.astype(np.int64), np.array([n, params.step, int(box), pad, band, low,
                                                   params.samples_per_subregion], np.int64),
                  j_resp, resp_w.copy(), j_desc, x.copy(), plan.desc_abs.sum(axis=1))
    # The kernel computes Haar responses as v[s] - 2 v[s+1] + v[s+2] and the signed sums from gauss, sample s in
    # subregion s // samples_per_subregion: that is surf1d's desc_haar / desc_abs, checked here once per plan so
    # that a change of their layout cannot pass unnoticed.
    s_n = jit.gauss.size
    sub = np.arange(s_n) // params.samples_per_subregion
    haar = np.zeros((s_n + 2, s_n))
    haar[np.arange(s_n), np.arange(s_n)], haar[np.arange(s_n) + 1, np.arange(s_n)] = 1.0, -2.0
    haar[np.arange(s_n) + 2, np.arange(s_n)] = 1.0
    signed = np.zeros_like(plan.desc_abs)
    signed[np.arange(s_n), 2 * sub] = jit.gauss
    if not (np.array_equal(plan.desc_haar, np.concatenate([haar, haar @ signed], axis=1))
            and np.array_equal(plan.desc_abs[np.arange(s_n), 2 * sub + 1], jit.gauss)):
        raise AssertionError("surf1d's descriptor tables changed layout: update loops/horizon/packed_jit.py")
    for a in (jit.rows, jit.geo, jit.resp_look, jit.resp_w, jit.desc_look, jit.x, jit.gauss):
        a.setflags(write=False)
    out = _BandPlan(None if contiguous else rows, starts[0], acc, lin, ext, resp_flat,
                    np.tile(resp_w, (n_bands, 1)), np.ascontiguousarray(desc_flat.T),
                    np.ascontiguousarray(desc_haar.T), np.ascontiguousarray(desc_abs.T), np.tile(x, n_bands),
                    code.astype(np.int64), (np.arange(n_bands) * m + m - 1)[:, None], low, m, n, jit)
    for a in (rows, out.lin, out.ext, out.resp_flat, out.resp_w, out.desc_t, out.desc_haar, out.desc_abs, out.x,
              out.code, out.null):
        if a is not None:
            a.setflags(write=False)
    return out


def extract_packed(image: np.ndarray, row: float | HorizonLine, params: HorizonParams,
                   compiled: bool | None = None) -> PackedBands:
    """Features of the `params.bands` bands around horizon `row` (a level HorizonLine is accepted), the
    `params.max_features` strongest per band.

    compiled: None (default) runs the compiled kernel when numba is installed, else the numpy code; True requires
    the kernel (HorizonError without numba); False always runs the numpy code. Same features either way.

    About 25 array calls whatever the number of bands (on a small frame their per-call cost is most of the time):
    band sums; one matrix product for every candidate's box-filter sum and every band's padded integral;
    extrema by array comparisons on all bands at once; the strongest of each band from one sort; the descriptors
    from one gather and two matrix products. The features are surf1d's (the tests check it on real frames).
    """
    k_max = params.max_features
    if k_max <= 0:
        raise HorizonError("the packed path needs max_features > 0 (a fixed number of slots per band)")
    if image.ndim != 2:
        image = as_gray(np.asarray(image))
    height, width = image.shape
    row = level_row(row)
    if not 0 <= row <= height - 1:     # bands are moved inside the image at its edges, a horizon is not
        raise HorizonError(f"horizon row {row:g} is outside the image (rows 0..{height - 1})")
    bp = _band_plan(height, width, row, params, image.dtype)
    jit = _use_compiled(compiled)
    if jit is not None:
        return _extract_compiled(jit, image, bp, params)
    n_bands, band = params.bands, params.band_height
    px = image[bp.r0:bp.r0 + n_bands * band] if bp.rows is None else image[bp.rows]
    if params.sample_mode is SampleMode.BOX:     # (B, n) box sums
        sums = px[:, :bp.n * params.step].reshape(n_bands, band, bp.n, params.step).sum(axis=(1, 3), dtype=bp.acc)
    else:                                        # (B, W) column sums, every step-th a signal sample
        sums = np.add.reduce(px.reshape(n_bands, band, width), axis=1, dtype=bp.acc)
    if bp.lin is not None:
        sig = sums if params.sample_mode is SampleMode.BOX else sums[:, ::params.step]
        out = np.matmul(sig.astype(bp.lin.dtype), bp.lin)               # (B, M + seg + 1), integers
        box_sums = out[:, :bp.m]
    else:
        out = cv2.integral(sums.ravel().take(bp.ext).reshape(1, -1), sdepth=cv2.CV_64F)[1]
        box_sums = np.matmul(RESP_COEF, out.take(bp.resp_flat)).reshape(n_bands, bp.m)
    # |response| of every candidate, float64 as surf1d, between two zeros (the flat vector's outer neighbours).
    a = np.zeros(params.bands * bp.m + 2)
    c = a[1:-1]
    np.abs(np.multiply(box_sums, bp.resp_w).ravel(), out=c)
    # Extrema in space (as surf1d): above the threshold, above the left neighbour, not below the right one.
    ext = c > np.maximum(a[:-2], params.threshold)
    ext &= c >= a[2:]
    # The k_max strongest of each band, strongest first, ties to the first position (surf1d's stable sort), by
    # one sort of int64 keys: a non-negative float's bit pattern orders as the float; its low bits are replaced
    # by the candidate's code (strengths closer than about 2^-40 relative count as equal). Not an extremum: key 0.
    low = bp.low
    key = c.view(np.int64) & ~low
    key |= bp.code
    key = np.where(ext, key, 0).reshape(params.bands, bp.m)
    top = np.sort(key, axis=1)[:, :-k_max - 1:-1]
    if top.shape[1] < k_max:                                            # fewer candidates than slots
        top = np.pad(top, ((0, 0), (0, k_max - top.shape[1])))
    cand = bp.null - (top & low)                                        # (B, K) flat candidates; null if empty
    # Descriptors as surf1d.detect_and_describe: integral look-ups -> Haar responses and subregion sums; feature
    # after feature along the last axis, so that the |Haar| rows are one contiguous block.
    cand = cand.ravel()
    # The last row of h is the candidate's box-filter sum (its sign is the blob's).
    h = bp.desc_haar @ out.ravel().take(bp.desc_t.take(cand, axis=1)).astype(np.float64)   # (S + D + 1, B * K)
    n_s = bp.desc_abs.shape[1] - bp.desc_abs.shape[0]
    np.abs(h[:n_s], out=h[:n_s])
    desc = bp.desc_abs @ h[:-1]                                         # (D, B * K)
    norm = np.sqrt(np.add.reduce(desc * desc, axis=0) + 1e-24)
    d = desc.shape[0]
    keys = np.empty((params.bands, k_max, d + 1), np.float32)
    keys_t = keys.reshape(-1, d + 1).T
    np.divide(desc, norm, out=keys_t[:d])
    np.multiply(np.sign(h[-1]), SIGN_WEIGHT, out=keys_t[d])             # +-SIGN_WEIGHT; 0 in an empty slot
    return PackedBands(bp.x.take(cand).reshape(params.bands, k_max), keys, top != 0, width)


def _extract_compiled(jit: ModuleType, image: np.ndarray, bp: _BandPlan, params: HorizonParams) -> PackedBands:
    # One kernel instance per image layout: 8-bit frames as they are, anything else as float64 (exact for integer
    # types); a strided view is copied once.
    if image.dtype != np.uint8 and image.dtype != np.float64:
        image = image.astype(np.float64)
    elif not image.flags.c_contiguous:
        image = np.ascontiguousarray(image)
    j, k_max = bp.jit, params.max_features
    x = np.empty((params.bands, k_max))
    keys = np.empty((params.bands, k_max, 2 * params.subregions + 1), np.float32)
    valid = np.empty((params.bands, k_max), np.bool_)
    jit.extract_kernel(image, j.rows, j.geo, j.resp_look, j.resp_w, j.desc_look, j.x, j.gauss,
                       float(params.threshold), x, keys, valid)
    return PackedBands(x, keys, valid, image.shape[1])


def stack_packed(views: list[PackedBands]) -> PackedSet:
    """Stored views side by side (all from the same bands and max_features)."""
    if not views:
        raise HorizonError("no views to stack")
    shapes = {v.keys.shape for v in views}
    if len(shapes) > 1:
        raise HorizonError(f"views of different bands / max_features cannot be stacked: key shapes {sorted(shapes)}")
    keys = np.stack([v.keys for v in views], axis=2)                    # (B, K, P, D2)
    valid = np.stack([v.valid for v in views], axis=2)                  # (B, K, P)
    x = np.stack([v.x for v in views], axis=2)
    return PackedSet(keys, x, valid.sum(axis=1) >= 2)


def match_packed(test: PackedBands, stored: PackedSet, params: HorizonParams,
                 which: np.ndarray | None = None, details: bool = False, compiled: bool | None = None
                 ) -> PackedScores:
    """Scores of `test` against every stored view (or the views `which`), as match_bands with Consensus.SHIFT;
    with `details`, also each view's consensus matches (PackedScores.matches, a PackedMatch per view).
    compiled: as extract_packed's (details are computed by the numpy code).

    Per band: all test features against all stored slots in one product; nearest and second nearest; the ratio
    and sign tests; weights 1 / max(distance, min_distance); NN score = their sum; consensus = the heaviest window
    of two adjacent ransac_tolerance bins of x_test - x_stored holding at least ransac_min_inliers matches.
    """
    if params.consensus is not Consensus.SHIFT or not params.match_sign or params.one_to_one:
        raise HorizonError("the packed path matches with consensus 'shift', match_sign true, one_to_one false")
    jit = None if details else _use_compiled(compiled)
    if jit is not None:
        return _match_compiled(jit, test, stored, params, which)
    keys, xs, enough = stored.keys, stored.x, stored.enough
    if which is not None:
        which = np.asarray(which, np.intp)
        keys, xs, enough = keys.take(which, axis=2), xs.take(which, axis=2), enough.take(which, axis=1)
    b, ks, p, d2 = keys.shape
    kt = test.keys.shape[1]
    if test.keys.shape != (b, ks, d2):
        raise HorizonError(f"test view of key shape {test.keys.shape} against stored views of {(b, ks, d2)}: "
                           "they come from different bands / max_features")
    if p == 0:
        return PackedScores(np.zeros(0), np.zeros(0), [] if details else None)
    # Every stored slot of every view against every test feature of the band, laid out (B, Ks, P, Kt): a max over
    # the stored slots is then an elementwise max of Ks contiguous (P, Kt) blocks per band.
    sim = np.matmul(keys.reshape(b, ks * p, d2), test.keys.transpose(0, 2, 1))   # (B, Ks * P, Kt)
    # Nearest and second nearest slot in two max passes over a copy whose low mantissa bits carry the slot index;
    # their exact similarities are then read from sim. Non-negative floats order as their int32 bit patterns, and
    # every negative one (opposite sign) is below them: the nearest is right whenever it is a match (> 0), and a
    # wrong second nearest is then <= 0, where the ratio test passes as it does with the true one (d1 <= 4,
    # d2 >= 10).
    bits = max(1, (ks - 1).bit_length())
    low = (1 << bits) - 1
    row, x_row, h_row = _match_index(b, kt, ks, p)
    si = np.bitwise_and(sim.view(np.int32), np.int32(~low)).reshape(b, ks, p, kt)
    si |= np.arange(ks, dtype=np.int32).reshape(ks, 1, 1)
    j1 = si.max(axis=1)
    j1 &= low                                                            # (B, P, Kt)
    at1 = row + j1 * (p * kt)                                            # flat (b, j1, v, t) in sim and si
    si.ravel()[at1] = np.iinfo(np.int32).min
    j2 = si.max(axis=1)
    j2 &= low
    flat_sim = sim.ravel()
    s1 = flat_sim[at1]
    d1 = 2.0 + 2.0 * SIGN_WEIGHT ** 2 - 2.0 * s1                         # squared descriptor distances
    d2 = 2.0 + 2.0 * SIGN_WEIGHT ** 2 - 2.0 * flat_sim[row + j2 * (p * kt)]
    ok = d1 < (params.ratio ** 2) * d2
    ok &= s1 > 0.0
    ok &= test.valid[:, None, :] & enough[:, :, None]
    w = ok / np.sqrt(np.maximum(d1, params.min_distance ** 2))          # 1 / max(distance, min_distance), or 0
    nn = w.sum(axis=(0, 2))
    if not ok.any():
        return PackedScores(nn, np.zeros(p), [_no_consensus(nn[v]) for v in range(p)] if details else None)
    # The shift histogram of every (band, view) in one bincount; each match adds its weight plus `unit`, so a
    # window's count and weight come out of the same sum (weights of one band sum to less than unit).
    x_stored = xs.ravel()[x_row + j1 * p]                                # (B, P, Kt): x of each nearest
    bins = shift_bins(test.x[:, None, :] - x_stored, params)
    matched = bins[ok]
    lo = int(matched.min())
    n_bins = int(matched.max()) - lo + 2
    bins -= lo
    bins = np.where(ok, bins, 0)                                         # unmatched: any bin, they add 0
    unit = 2.0 ** np.ceil(np.log2(kt / params.min_distance + 1.0))
    w_count = w + unit * ok
    h = np.bincount((h_row * n_bins + bins).ravel(), weights=w_count.ravel(), minlength=b * p * n_bins)
    h = h.reshape(b, p, n_bins)
    hw = h[..., :-1] + h[..., 1:]
    count = np.floor(hw / unit)
    hw -= unit * count
    hw[count < params.ransac_min_inliers] = 0.0
    consensus = hw.max(axis=2).sum(axis=0)
    if not details:
        return PackedScores(nn, consensus)
    # The consensus matches: those in each (band, view)'s heaviest window, when it qualified.
    k = hw.argmax(axis=2)                                                # (B, P)
    k = np.where(hw.max(axis=2) > 0, k, -2)[:, :, None]                  # -2: no window (no bin is -2 or -1)
    inl = ok & ((bins == k) | (bins == k + 1))                           # (B, P, Kt)
    x_test = np.broadcast_to(test.x[:, None, :], inl.shape)
    band = np.broadcast_to(np.arange(b)[:, None, None], inl.shape)
    out = []
    for v in range(p):
        m = inl[:, v]
        xt, xv = x_test[:, v][m], x_stored[:, v][m]
        b_d = float(np.mean(xt - xv)) if m.any() else float("nan")
        out.append(PackedMatch(float(nn[v]), float(consensus[v]), 1.0 if m.any() else float("nan"), b_d, xt, xv,
                               band[:, v][m]))
    return PackedScores(nn, consensus, out)


def _match_compiled(jit: ModuleType, test: PackedBands, stored: PackedSet, params: HorizonParams,
                    which: np.ndarray | None) -> PackedScores:
    b, ks, p, d2 = stored.keys.shape
    if test.keys.shape != (b, ks, d2):
        raise HorizonError(f"test view of key shape {test.keys.shape} against stored views of {(b, ks, d2)}: "
                           "they come from different bands / max_features")
    which = _all_views(p) if which is None else np.asarray(which, np.int64).reshape(-1)
    nn, cons = np.empty(which.shape[0], np.float32), np.empty(which.shape[0])
    bad = jit.match_kernel(test.keys, test.x, test.valid, stored.keys, stored.x, stored.enough, which,
                           float(params.ratio), float(params.min_distance), float(params.ransac_tolerance),
                           int(params.ransac_min_inliers), nn, cons)
    if bad:
        raise HorizonError(f"{bad} stored view indices outside the {p} stored views")
    return PackedScores(nn, cons)


@functools.lru_cache(maxsize=64)
def _all_views(p: int) -> np.ndarray:
    return np.arange(p, dtype=np.int64)     # writable, as a caller's `which`: one kernel instance for both


def _no_consensus(score: float) -> PackedMatch:
    none = np.zeros(0)
    return PackedMatch(float(score), 0.0, float("nan"), float("nan"), none, none, np.zeros(0, np.intp))


@functools.lru_cache(maxsize=64)
def _match_index(b: int, kt: int, ks: int, p: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat indices of slot 0 of each (band, view, test slot) in the (B, Ks, P, Kt) similarities, of each (band,
    view) in the (B, Ks, P) stored columns and in the (B, P, bins) histogram (times its bin count)."""
    row = np.arange(b).reshape(b, 1, 1) * (ks * p * kt) + np.arange(p * kt).reshape(1, p, kt)
    x_row = np.arange(b).reshape(b, 1, 1) * (ks * p) + np.arange(p).reshape(1, p, 1)
    h_row = np.arange(b).reshape(b, 1, 1) * p + np.arange(p).reshape(1, p, 1)
    for a in (row, x_row, h_row):
        a.setflags(write=False)
    return row, x_row, h_row
