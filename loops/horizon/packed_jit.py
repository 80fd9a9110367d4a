"""Compiled kernels of the packed 1D SURF path (loops.horizon.packed), with numba (the optional extra `fast`).

On the small frames the packed path is made for, its numpy form spends nearly all of its time in the fixed cost of
a few dozen array calls (about 1.2 us each), not in arithmetic. Here one extraction and one matching call are each
one compiled function running plain loops over contiguous arrays, so a lone pair costs a few microseconds of
arithmetic plus two call dispatches.

Same results as the numpy path: the same candidates (surf1d's padded integral and look-up tables, built once per
frame size by loops.horizon.packed), the same extremum test, the same int64 sort keys for the strongest of each
band, the same int32-masked nearest / second-nearest choice and float32 ratio test. Sums are exact integers on
8-bit frames, so the responses and the selected features are identical; descriptor values and scores may differ
in the last float bits (different summation order), as the numpy path differs from surf1d's. The similarities are
summed with float32 fused multiply-adds (LLVM's fma, through llvmlite, numba's own code generator), as BLAS's
sgemm does in the numpy path.

`cache=True`: compiled once per machine (about 6 s for the extraction kernel and 5 s for the matching kernel on
our shared 2-core machine, per image dtype: uint8, float64), then loaded from numba's cache (its __pycache__ or
NUMBA_CACHE_DIR): about 1.1 s for the first kernel of a process (numba's start-up), 20-30 ms for the next.

This module imports numba at its top; loops.horizon.packed loads it only when numba is installed and the compiled
path is first used, so `import loops.horizon` does not pay numba's import time.
"""
from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from loops.horizon.surf1d import SIGN_WEIGHT  # a global scalar: numba compiles it in as a constant


@intrinsic
def fma32(typingctx, a, b, c):
    """a * b + c rounded once, in float32 (LLVM's fma: one instruction where the CPU has it), as BLAS's sgemm sums
    its products; numba has no fused multiply-add of its own."""
    sig = types.float32(types.float32, types.float32, types.float32)

    def codegen(context, builder, signature, args):
        flt = ir.FloatType()
        fn = builder.module.declare_intrinsic("llvm.fma", [flt], ir.FunctionType(flt, [flt, flt, flt]))
        return builder.call(fn, args)

    return sig, codegen


@numba.njit(cache=True, nogil=True)
def extract_kernel(image, rows, geo, resp_look, resp_w, desc_look, x_cand, gauss, threshold, out_x, out_keys,
                   out_valid):
    """Features of every band of `image` into out_x (B, K), out_keys (B, K, D + 1), out_valid (B, K).

    The band's signal, its padded integral and the box-filter sums are float64: exact for integer pixel values.
    rows: (B * band_height,) image rows, band after band. geo: int64 [n samples, step, box sampling 0/1, pad,
    band_height, low, samples per subregion]: signal length, columns per sample, sampling mode, the integral's
    padding, rows per band, the sort key's low-bit mask, descriptor samples per subregion. Per candidate j of a band (M, separators included, with weight 0 and look-ups 0):
    resp_look (M, 4) look-ups of its box filter in the padded integral, resp_w (M,) response weight, desc_look
    (M, S + 2) descriptor look-ups, x_cand (M,) image column. gauss (S,): the Gaussian weight of each descriptor
    sample, subregion after subregion (surf1d's desc_haar / desc_abs, whose structure this uses).
    """
    n, step, box, pad, band, low, per_sub = geo[0], geo[1], geo[2], geo[3], geo[4], geo[5], geo[6]
    n_bands, k_max = out_x.shape
    m = resp_w.shape[0]
    d = out_keys.shape[2] - 1
    seg = n + 2 * pad
    width = image.shape[1]
    colsum = np.zeros(width)
    sig = np.zeros(n)
    integ = np.zeros(seg + 1)
    box_sum = np.zeros(m)
    strength = np.zeros(m)
    bits = strength.view(np.int64)      # a non-negative float64 orders as its int64 bit pattern
    top = np.zeros(k_max, np.int64)
    desc = np.zeros(d)
    for b in range(n_bands):
        # The band's signal: column sums every step-th column, or sums over each sample's step columns.
        # (Whole rows summed into column sums first: contiguous, vectorised; exact integers on 8-bit frames.)
        colsum[:] = 0.0
        for r in range(b * band, (b + 1) * band):
            line = image[rows[r]]
            for c in range(width):
                colsum[c] += line[c]
        for i in range(n):
            if box:
                acc = 0.0
                for c in range(i * step, i * step + step):
                    acc += colsum[c]
                sig[i] = acc
            else:
                sig[i] = colsum[i * step]
        # The padded integral (surf1d's, less padding): the ends replicated pad samples out, a leading 0.
        acc = 0.0
        for t in range(pad):
            acc += sig[0]
            integ[t + 1] = acc
        for t in range(n):
            acc += sig[t]
            integ[pad + t + 1] = acc
        for t in range(pad + n, seg):
            acc += sig[n - 1]
            integ[t + 1] = acc
        for j in range(m):
            s = (integ[resp_look[j, 0]] - integ[resp_look[j, 1]] - 3.0 * integ[resp_look[j, 2]]
                 + 3.0 * integ[resp_look[j, 3]])
            box_sum[j] = s
            strength[j] = abs(s * resp_w[j])
        # Extrema (above the threshold, above the left neighbour, not below the right one; a band's first and last
        # candidates are separators of strength 0) and the k_max strongest by int64 key: the strength's bits with
        # the low ones replaced by M - 1 - j (ties to the first candidate), kept in descending order.
        top[:] = 0
        for j in range(1, m - 1):
            c = strength[j]
            if c > strength[j - 1] and c > threshold and c >= strength[j + 1]:
                key = (bits[j] & ~low) | (m - 1 - j)
                if key > top[k_max - 1]:
                    k = k_max - 1
                    while k > 0 and top[k - 1] < key:
                        top[k] = top[k - 1]
                        k -= 1
                    top[k] = key
        for k in range(k_max):
            if top[k] == 0:                  # an empty slot: column 0, keys 0
                out_x[b, k] = 0.0
                out_valid[b, k] = False
                for u in range(d + 1):
                    out_keys[b, k, u] = 0.0
                continue
            j = m - 1 - (top[k] & low)
            out_x[b, k] = x_cand[j]
            out_valid[b, k] = True
            # Descriptor as surf1d: Haar response dx of size 2q at each sample (three integral look-ups shared
            # with its neighbours), per subregion the Gaussian-weighted sums of dx and |dx|, unit length.
            look = desc_look[j]
            v0, v1 = integ[look[0]], integ[look[1]]
            norm = 0.0
            for u in range(d // 2):
                sd = 0.0
                sa = 0.0
                for s in range(u * per_sub, (u + 1) * per_sub):
                    v2 = integ[look[s + 2]]
                    dx = v0 - 2.0 * v1 + v2
                    v0, v1 = v1, v2
                    sd += gauss[s] * dx
                    sa += gauss[s] * abs(dx)
                desc[2 * u] = sd
                desc[2 * u + 1] = sa
                norm += sd * sd + sa * sa
            norm = np.sqrt(norm + 1e-24)
            for u in range(d):
                out_keys[b, k, u] = desc[u] / norm
            out_keys[b, k, d] = SIGN_WEIGHT if box_sum[j] > 0 else -SIGN_WEIGHT
    return 0


@numba.njit(cache=True, nogil=True)
def match_kernel(t_keys, t_x, t_valid, s_keys, s_x, enough, which, ratio, min_distance, tol, min_inl, out_nn,
                 out_cons):
    """NN and shift-consensus scores of one test view against the stored views `which`, into out_nn / out_cons;
    returns the number of indices of `which` outside the stored set (nothing is scored then).

    t_keys (B, Kt, D2) float32, t_x (B, Kt), t_valid (B, Kt): the test view. s_keys (B, Ks, P, D2), s_x (B, Ks, P),
    enough (B, P): the stored set. which (Q,): stored views, negative ones counted from the end (as numpy's take).
    ratio, min_distance, tol (ransac_tolerance), min_inl (ransac_min_inliers): HorizonParams'.
    """
    n_bands, kt, d2 = t_keys.shape
    ks, n_views = s_keys.shape[1], s_keys.shape[2]
    q = which.shape[0]
    bad = 0
    for i in range(q):
        if which[i] < -n_views or which[i] >= n_views:
            bad += 1
    if bad:
        return bad
    r2 = np.float32(ratio * ratio)
    md2 = np.float32(min_distance * min_distance)
    n_bits = 1
    while (1 << n_bits) < ks:
        n_bits += 1
    low = np.int32((1 << n_bits) - 1)
    high = np.int32(~low)
    sim = np.zeros((ks, kt), np.float32)
    sim_bits = sim.view(np.int32)
    t_keys_t = np.zeros((d2, kt), np.float32)
    best1 = np.zeros(kt, np.int32)
    best2 = np.zeros(kt, np.int32)
    w = np.zeros(kt)
    bins = np.zeros(kt, np.int64)
    ten = np.float32(2.0 + 2.0 * SIGN_WEIGHT ** 2)    # |a - b|^2 = ten - 2 a.b for keys with unit descriptors
    two = np.float32(2.0)
    one = np.float32(1.0)
    nn_sum = np.zeros(q)
    for i in range(q):
        out_cons[i] = 0.0
    for b in range(n_bands):
        for t in range(kt):
            for u in range(d2):
                t_keys_t[u, t] = t_keys[b, t, u]
        for i in range(q):
            p = which[i] if which[i] >= 0 else which[i] + n_views
            if not enough[b, p]:
                continue
            # Every stored slot against every test slot, the test slots side by side (contiguous: the inner loop is
            # vectorised). Summed over the key in order with a fused multiply-add in float32, as the numpy path's
            # BLAS sgemm does: the distances 10 - 2 a.b of near matches cancel most digits, so the last bit of a.b
            # shows in their 1 / distance weights.
            for t in range(kt):
                best1[t] = np.int32(-2147483648)
                best2[t] = np.int32(-2147483648)
            for j in range(ks):
                for t in range(kt):
                    sim[j, t] = 0.0
                for u in range(d2):
                    a = s_keys[b, j, p, u]
                    for t in range(kt):
                        sim[j, t] = fma32(a, t_keys_t[u, t], sim[j, t])
                # Nearest and second nearest stored slot of every test slot by the similarity's int32 bits with the
                # low bits replaced by the slot index (as the numpy path: the nearest is exact whenever it is a
                # match); keys are distinct, so the second is the largest below the first.
                for t in range(kt):
                    key = (sim_bits[j, t] & high) | np.int32(j)
                    b1 = best1[t]
                    best2[t] = max(best2[t], min(b1, key))
                    best1[t] = max(b1, key)
            n_ok = 0
            nn = 0.0
            for t in range(kt):
                if not t_valid[b, t]:
                    continue
                j1 = best1[t] & low
                j2 = best2[t] & low
                s1 = sim[j1, t]
                if not s1 > np.float32(0.0):
                    continue
                dd1 = ten - two * s1
                dd2 = ten - two * sim[j2, t]
                if not dd1 < r2 * dd2:
                    continue
                wt = one / np.sqrt(max(dd1, md2))
                nn += wt
                w[n_ok] = wt
                bins[n_ok] = np.int64(np.floor((t_x[b, t] - s_x[b, j1, p]) / tol))
                n_ok += 1
            # The heaviest window of two adjacent shift bins holding at least min_inl matches.
            best = 0.0
            for a in range(n_ok):
                for start in (bins[a] - 1, bins[a]):
                    cnt = 0
                    tot = 0.0
                    for c in range(n_ok):
                        if bins[c] == start or bins[c] == start + 1:
                            cnt += 1
                            tot += w[c]
                    if cnt >= min_inl and tot > best:
                        best = tot
            nn_sum[i] += nn
            out_cons[i] += best
    for i in range(q):
        out_nn[i] = nn_sum[i]
    return 0
