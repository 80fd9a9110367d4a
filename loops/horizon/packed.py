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
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from loops.horizon.bands import band_rows
from loops.horizon.matching import shift_bins
from loops.horizon.params import Consensus, HorizonParams, SampleMode
from loops.horizon.signal import HorizonError, as_gray
from loops.horizon.surf1d import RESP_COEF, SIGN_WEIGHT, min_signal_length, signal_plan

INVALID = -1.0e4   # key bias of an empty slot: its similarity to any test feature is below every real one


@dataclass(frozen=True)
class PackedBands:
    """1D SURF features of every band of one view, at most K per band (empty slots have valid False).

    x: (B, K) image column of each feature. keys: (B, K, D + 2) float32, the descriptor (unit length), its sign
    times SIGN_WEIGHT and a bias (0 valid, INVALID empty), so that one product gives descriptor distances, the
    sign test and the exclusion of empty slots. response: (B, K) scale-normalised response. width: image columns.
    """

    x: np.ndarray
    keys: np.ndarray
    valid: np.ndarray
    response: np.ndarray
    width: int

    @property
    def counts(self) -> np.ndarray:
        """Features per band."""
        return self.valid.sum(axis=1)


@dataclass(frozen=True)
class PackedSet:
    """P stored views, laid out for matching: keys_t (B, D + 2, P * K) (view p's slots at p * K .. p * K + K - 1),
    x (B, P, K), enough (B, P): band holds at least two features (nearest and second nearest exist)."""

    keys_t: np.ndarray
    x: np.ndarray
    enough: np.ndarray

    def __len__(self) -> int:
        return int(self.x.shape[1])


@dataclass(frozen=True)
class PackedScores:
    """Scores of one test view against P stored views: NN and consensus sums over the bands, (P,) each."""

    score: np.ndarray
    score_ransac: np.ndarray


@dataclass(frozen=True)
class _BandPlan:
    rows: np.ndarray      # (B * band_height,) image rows, band after band
    ext_idx: np.ndarray   # (L,) signal index of each padded-integral input (index n = a zero column)
    resp_idx: np.ndarray  # (4, M) integral look-ups of the candidates of levels that fit the signal
    resp_w: np.ndarray    # (M,)
    cand: np.ndarray      # (M,) index of each kept candidate in the 1D plan
    n: int


@functools.lru_cache(maxsize=64)
def _band_plan(height: int, width: int, row: float, params: HorizonParams) -> _BandPlan:
    n = width // params.step if params.sample_mode is SampleMode.BOX else -(-width // params.step)
    if n < min_signal_length(params):
        raise HorizonError(f"horizon signal too short: {n} samples (image width {width} / step {params.step}); "
                           f"1D SURF needs at least {min_signal_length(params)}")
    band = params.band_height
    rows = []
    for r in band_rows(row, height, params):
        r0 = int(np.floor(r + 0.5)) - band // 2
        if r0 < 0 or r0 + band > height:
            raise HorizonError(f"horizon row {row:g}: a {band}-pixel band needs rows {r0}..{r0 + band - 1}, but "
                               f"the image has rows 0..{height - 1}")
        rows.append(np.arange(r0, r0 + band))
    plan = signal_plan(n, params)
    pad = plan.pad
    ext_idx = np.concatenate([[n], np.zeros(pad, np.intp), np.arange(n), np.full(pad, n - 1)]).astype(np.intp)
    # Levels whose filter never fits the signal give zero responses everywhere: skip them (each kept level keeps
    # all its candidates, so its first and last still separate it from its neighbours in the flat vector).
    used = np.unique(plan.cand_level[plan.resp_weight > 0])
    keep = np.flatnonzero(np.isin(plan.cand_level, used))
    out = _BandPlan(np.concatenate(rows), ext_idx, np.ascontiguousarray(plan.resp_idx[:, keep]),
                    plan.resp_weight[keep], keep, n)
    for a in (out.rows, out.ext_idx, out.resp_idx, out.resp_w, out.cand):
        a.setflags(write=False)
    return out


def extract_packed(image: np.ndarray, row: float, params: HorizonParams) -> PackedBands:
    """Features of the `params.bands` bands around horizon `row`, the `params.max_features` strongest per band."""
    k_max = params.max_features
    if k_max <= 0:
        raise HorizonError("the packed path needs max_features > 0 (a fixed number of slots per band)")
    image = as_gray(np.asarray(image))
    height, width = image.shape
    bp = _band_plan(height, width, float(row), params)
    plan = signal_plan(bp.n, params)
    n_bands, band, n = params.bands, params.band_height, bp.n
    sig = np.zeros((n_bands, n + 1))                          # column n stays 0: the integral's leading zero
    if params.sample_mode is SampleMode.BOX:
        px = image[bp.rows, :n * params.step].reshape(n_bands, band, n, params.step)
        sig[:, :n] = px.sum(axis=(1, 3), dtype=np.float64)
    else:
        np.add.reduce(image[bp.rows, ::params.step].reshape(n_bands, band, n), axis=1, dtype=np.float64,
                      out=sig[:, :n])
    integral = np.cumsum(sig[:, bp.ext_idx], axis=1)          # (B, L), as surf1d._padded_integral per band
    r = np.matmul(RESP_COEF, integral[:, bp.resp_idx])       # (B, M)
    r *= bp.resp_w
    a = np.abs(r)
    c = a[:, 1:-1]
    bi, ci = np.nonzero((c > np.maximum(a[:, :-2], params.threshold)) & (c >= a[:, 2:]))   # band, then position
    # The k_max strongest of each band (ties: the first position, as surf1d), into slots 0.. in that order.
    order = np.lexsort((-c[bi, ci], bi))
    bi, ci = bi[order], ci[order]
    counts = np.bincount(bi, minlength=n_bands)
    slot = np.arange(bi.size) - (np.cumsum(counts) - counts)[bi]
    keep = slot < k_max
    bi, ci, slot = bi[keep], ci[keep], slot[keep]
    cand = bp.cand[ci + 1]                                       # kept candidates, in the 1D plan
    # Descriptors as surf1d.detect_and_describe: integral look-ups -> Haar responses and subregion sums.
    out = integral.ravel()[plan.desc_idx[cand] + (bi * integral.shape[1])[:, None]] @ plan.desc_haar
    n_s = plan.desc_abs.shape[0]
    desc = np.abs(out[:, :n_s]) @ plan.desc_abs
    desc += out[:, n_s:]
    desc /= np.sqrt(np.einsum("kd,kd->k", desc, desc) + 1e-24)[:, None]
    resp = r[bi, ci + 1]
    d = desc.shape[1]
    keys = np.zeros((n_bands, k_max, d + 2), np.float32)
    keys[..., d + 1] = INVALID
    keys[bi, slot, :d] = desc
    keys[bi, slot, d] = np.sign(resp) * SIGN_WEIGHT
    keys[bi, slot, d + 1] = 0.0
    valid = np.zeros((n_bands, k_max), bool)
    valid[bi, slot] = True
    x = np.zeros((n_bands, k_max))
    x[bi, slot] = plan.columns[plan.cand_pos[cand]]
    response = np.zeros((n_bands, k_max))
    response[bi, slot] = resp
    return PackedBands(x, keys, valid, response, width)


def stack_packed(views: list[PackedBands]) -> PackedSet:
    """Stored views side by side (they must come from the same bands and max_features)."""
    if not views:
        raise ValueError("no views to stack")
    keys = np.stack([v.keys for v in views], axis=1)                 # (B, P, K, D2)
    b, p, k, d2 = keys.shape
    keys_t = np.ascontiguousarray(keys.transpose(0, 3, 1, 2)).reshape(b, d2, p * k)
    valid = np.stack([v.valid for v in views], axis=1)               # (B, P, K)
    return PackedSet(keys_t, np.stack([v.x for v in views], axis=1), valid.sum(axis=2) >= 2)


def match_packed(test: PackedBands, stored: PackedSet, params: HorizonParams,
                 which: np.ndarray | None = None) -> PackedScores:
    """Scores of `test` against every stored view (or the views `which`), as match_bands with Consensus.SHIFT.

    Per band: all test features against all stored slots in one product; nearest and second nearest; the ratio
    and sign tests; weights 1 / max(distance, min_distance); NN score = their sum; consensus = the heaviest window
    of two adjacent ransac_tolerance bins of x_test - x_stored holding at least ransac_min_inliers matches.
    """
    if params.consensus is not Consensus.SHIFT:
        raise HorizonError("the packed path scores with consensus 'shift' only")
    keys_t, xs, enough = stored.keys_t, stored.x, stored.enough
    b, d2, pk = keys_t.shape
    k = xs.shape[2]
    if which is not None:
        which = np.asarray(which, np.intp)
        cols = (which[:, None] * k + np.arange(k)).ravel()
        keys_t, xs, enough = keys_t[:, :, cols], xs[:, which], enough[:, which]
        pk = cols.size
    p = pk // k
    q = test.keys.copy()
    q[..., -1] = 1.0                                                 # picks up each stored slot's bias
    sim = np.matmul(q, keys_t).reshape(b, q.shape[1], p, k)          # (B, Kt, P, Ks)
    j1 = sim.argmax(axis=3)[..., None]
    s1 = np.take_along_axis(sim, j1, axis=3)[..., 0]
    np.put_along_axis(sim, j1, -np.inf, axis=3)
    s2 = sim.max(axis=3)
    base = 2.0 + 2.0 * SIGN_WEIGHT ** 2 if params.match_sign else 2.0
    if not params.match_sign:
        raise HorizonError("the packed path applies the sign test (match_sign true)")
    if params.one_to_one:
        raise HorizonError("the packed path has no one-to-one matching")
    d1 = base - 2.0 * s1
    ok = (d1 < (params.ratio ** 2) * (base - 2.0 * s2)) & (s1 > 0.0)
    ok &= test.valid[:, :, None] & enough[:, None, :]
    w = np.where(ok, 1.0 / np.maximum(np.sqrt(np.maximum(d1, 0.0)), params.min_distance), 0.0)   # (B, Kt, P)
    nn = w.sum(axis=(0, 1))
    # x of each nearest stored slot, then the shift histogram of every (band, view) in one bincount.
    x_best = np.take_along_axis(xs[:, None, :, :], j1, axis=3)[..., 0]                            # (B, Kt, P)
    bins = shift_bins(test.x[:, :, None] - x_best, params)
    lo = int(np.floor(-stored.x.max() / params.ransac_tolerance)) - 1
    n_bins = int(np.floor(test.width / params.ransac_tolerance)) - lo + 2
    bins = np.clip(bins - lo, 0, n_bins - 1)
    flat = (np.arange(b * p).reshape(b, 1, p) * n_bins + bins).ravel()
    h = np.bincount(flat, weights=w.ravel(), minlength=b * p * n_bins).reshape(b, p, n_bins)
    c = np.bincount(flat, weights=ok.ravel(), minlength=b * p * n_bins).reshape(b, p, n_bins)
    hw = h[..., :-1] + h[..., 1:]
    hw[(c[..., :-1] + c[..., 1:]) < params.ransac_min_inliers] = 0.0
    return PackedScores(nn, hw.max(axis=2).sum(axis=0))
