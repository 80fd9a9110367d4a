"""The Hamming kernel for packed binary descriptors (uint8 rows of bits): XOR + popcount, in numpy, no BLAS.

Rows are compared as 64-bit words when their length allows it (8x fewer popcounts); other lengths are padded with
zero bytes, which change no distance.
"""
from __future__ import annotations

import numpy as np


def bit_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Set bits of a ^ b per element (any unsigned integer arrays that broadcast), as uint8: the Hamming distance
    of aligned words, e.g. per-cluster signatures."""
    return np.bitwise_count(a ^ b)


def pad8(x: np.ndarray) -> np.ndarray:
    """Pad rows to a multiple of 8 bytes with zeros (zeros do not change Hamming distances)."""
    extra = (-x.shape[1]) % 8
    if not extra:
        return np.ascontiguousarray(x)
    out = np.zeros((x.shape[0], x.shape[1] + extra), dtype=np.uint8)   # (np.pad costs ~50 us per call)
    out[:, : x.shape[1]] = x
    return out


def hamming_matrix(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """All-pairs Hamming distances (Na, Nb) as uint16 of packed descriptors (rows of the same byte length).
    XOR + popcount per 64-bit word with preallocated temporaries: ~2x faster than two OpenCV batchDistance calls."""
    a, b = pad8(np.asarray(a, np.uint8)), pad8(np.asarray(b, np.uint8))
    wa, wb = a.view(np.uint64).T.copy(), b.view(np.uint64).T.copy()    # one contiguous row per 64-bit word
    t = np.empty((wa.shape[1], wb.shape[1]), dtype=np.uint64)
    c = np.empty(t.shape, dtype=np.uint8)
    d = np.zeros(t.shape, dtype=np.uint16)
    for w in range(wa.shape[0]):     # no allocation per word
        np.bitwise_xor(wa[w][:, None], wb[w][None, :], out=t)
        np.add(d, np.bitwise_count(t, out=c), out=d)
    return d


def _words(a: np.ndarray) -> np.ndarray:
    """Packed bits seen as uint64 words when the row length allows it: 8x fewer popcounts."""
    if a.shape[-1] % 8 == 0 and a.flags.c_contiguous:
        return a.view(np.uint64)
    return a


def _popcount_rows(words: np.ndarray) -> np.ndarray:
    """Set bits summed over the last axis, as int32. Adding the few word columns one by one is twice as fast as a
    reduction over a short last axis."""
    bc = np.bitwise_count(words)
    if bc.shape[-1] > 16:
        return bc.sum(axis=-1, dtype=np.int32)
    total = bc[..., 0].astype(np.int32)
    for i in range(1, bc.shape[-1]):
        total += bc[..., i]
    return total


def hamming_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamming distances (int32) between rows of a and b that broadcast against each other over all axes but the
    last (the bytes): a (N, D) with b (N, D) pairs rows; a (N, 1, D) with b (N, M, D) gives each row its own
    candidates."""
    return _popcount_rows(_words(np.ascontiguousarray(a)) ^ _words(np.ascontiguousarray(b)))
