"""Vectorised bit coding helpers: Rice codes for sorted coordinate indices (split into a unary and a fixed-width
stream so both encode and decode stay vectorised), and fixed-width bit fields."""
from __future__ import annotations

import numpy as np


def rice_cost(gaps: np.ndarray, k: int) -> int:
    """Bits used by Rice coding `gaps` (non-negative ints) with parameter k."""
    return int(np.sum(gaps >> k)) + len(gaps) * (1 + k)


def best_rice_k(gaps: np.ndarray, k_max: int = 20) -> int:
    """The Rice parameter minimising the coded size."""
    if len(gaps) == 0:
        return 0
    # the optimum is near log2(mean gap): search a small window around it
    centre = int(np.log2(max(float(np.mean(gaps)), 1.0)))
    ks = range(max(0, centre - 2), min(k_max, centre + 2) + 1)
    costs = [rice_cost(gaps, k) for k in ks]
    return ks[int(np.argmin(costs))]


def rice_encode(gaps: np.ndarray, k: int) -> tuple[bytes, bytes]:
    """Rice-code non-negative ints; returns (unary stream, remainder stream), each MSB-first and zero-padded.

    Unary part of a value v: (v >> k) one-bits then a zero; remainder: the low k bits of v."""
    g = np.asarray(gaps, dtype=np.int64)
    q = g >> k
    n_unary = int(q.sum()) + len(g)
    unary = np.ones(n_unary, dtype=np.uint8)
    if len(g):
        unary[np.cumsum(q + 1) - 1] = 0
    rem = fixed_bits(g & ((1 << k) - 1), k) if k else np.zeros(0, dtype=np.uint8)
    return np.packbits(unary).tobytes(), np.packbits(rem).tobytes()


def rice_decode(unary: bytes, rem: bytes, n: int, k: int) -> np.ndarray:
    """Inverse of rice_encode for n values; raises ValueError when the streams do not hold n values."""
    bits = np.unpackbits(np.frombuffer(unary, dtype=np.uint8))
    zeros = np.flatnonzero(bits == 0)
    if len(zeros) < n:
        raise ValueError(f"coordinate stream holds {len(zeros)} codes, {n} expected")
    zeros = zeros[:n]
    if n and zeros[-1] // 8 != len(unary) - 1:
        raise ValueError("coordinate stream has trailing bytes")
    q = np.diff(zeros, prepend=-1) - 1
    if k:
        if len(rem) * 8 < n * k:
            raise ValueError("coordinate remainder stream is too short")
        r = read_fixed_bits(np.unpackbits(np.frombuffer(rem, dtype=np.uint8))[: n * k], k)
    else:
        r = np.zeros(n, dtype=np.int64)
    return (q.astype(np.int64) << k) | r


def fixed_bits(values: np.ndarray, k: int) -> np.ndarray:
    """(n,) ints -> (n*k,) bits, each value MSB-first on k bits."""
    v = np.asarray(values, dtype=np.int64)
    shifts = np.arange(k - 1, -1, -1, dtype=np.int64)
    return ((v[:, None] >> shifts) & 1).astype(np.uint8).ravel()


def read_fixed_bits(bits: np.ndarray, k: int) -> np.ndarray:
    """Inverse of fixed_bits."""
    b = np.asarray(bits, dtype=np.int64).reshape(-1, k)
    return b @ (1 << np.arange(k - 1, -1, -1, dtype=np.int64))
