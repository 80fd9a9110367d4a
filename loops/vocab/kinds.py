"""Descriptor kinds, kept apart from the vocabulary tree (as in DBoW2) so one tree serves every descriptor.

BINARY: packed bit strings (uint8 rows, e.g. 32 bytes = 256 bits), Hamming distance (loops.hamming),
        majority-bit centres.
FLOAT:  real vectors (float32 rows), Euclidean distance, mean centres.
"""
from __future__ import annotations

import enum

import numpy as np
from scipy.sparse import csr_matrix

from loops.hamming import hamming_matrix, hamming_rows

_BYTE_HIST_BINS = 1 << 20   # largest (cluster, byte, value) histogram cluster_sums builds instead of unpacking bits
_BYTE_BITS = np.unpackbits(np.arange(256, dtype=np.uint8)[:, None], axis=1).astype(np.float64)  # (256, 8), MSB first
_BYTE_BITS.setflags(write=False)


class DescriptorKind(str, enum.Enum):
    BINARY = "binary"
    FLOAT = "float"


def kind_of(descriptors: np.ndarray) -> DescriptorKind:
    if descriptors.dtype == np.uint8:
        return DescriptorKind.BINARY
    if descriptors.dtype.kind == "f":
        return DescriptorKind.FLOAT
    raise ValueError(f"descriptors of dtype {descriptors.dtype}: expected packed uint8 bits or float32 vectors")


def as_storage(descriptors: np.ndarray, kind: DescriptorKind) -> np.ndarray:
    """The contiguous array the tree works on: uint8 bits, or float32."""
    dtype = np.uint8 if kind is DescriptorKind.BINARY else np.float32
    return np.ascontiguousarray(descriptors, dtype=dtype)


def distances(kind: DescriptorKind, x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distances between rows of x (n, D) and of c (m, D) -> (n, m) float32 (Hamming bits, or Euclidean)."""
    if kind is DescriptorKind.BINARY:
        return hamming_matrix(x, c).astype(np.float32)
    d2 = (x * x).sum(1)[:, None] - 2.0 * (x @ c.T) + (c * c).sum(1)[None, :]
    return np.sqrt(np.maximum(d2, 0.0)).astype(np.float32)


def batched_distances(kind: DescriptorKind, x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distances from each row x[i] (n, D) to its own candidates c[i] (n, m, D) -> (n, m)."""
    if kind is DescriptorKind.BINARY:
        return hamming_rows(np.ascontiguousarray(x)[:, None, :], c).astype(np.float32)
    diff = c - x[:, None, :]
    return np.sqrt(np.einsum("nmd,nmd->nm", diff, diff))


def paired_distances(kind: DescriptorKind, x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance between each row x[i] and c[i] (both (n, D)) -> (n,) float32."""
    if kind is DescriptorKind.BINARY:
        return hamming_rows(x, c).astype(np.float32)
    diff = x - c
    return np.sqrt(np.einsum("nd,nd->n", diff, diff)).astype(np.float32)


def cluster_sums(kind: DescriptorKind, x: np.ndarray, labels: np.ndarray, n_clusters: int,
                 bits: np.ndarray | None = None, weights: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Per cluster: the sum of its rows (bit counts, int32, for binary rows; float64 sums for float rows) and its
    size. Few binary clusters: a histogram of the packed bytes; otherwise one sparse product (one-hot cluster x row)
    @ rows. Both are exact in integers, with no BLAS over the rows (whose threads stall on a loaded machine) and no
    slow scatter-adds. Pass `bits` = unpacked_bits(x) to save unpacking; `weights` (+1 / -1 per row) turns the sums
    into signed updates."""
    sizes = np.bincount(labels, minlength=n_clusters)
    if kind is DescriptorKind.BINARY and n_clusters * x.shape[1] * 256 <= _BYTE_HIST_BINS:
        # few clusters (the top of the tree, where every row is still in play): histogram the packed bytes per
        # (cluster, byte position, byte value), then expand each byte value into its 8 bits; no unpacking
        d = x.shape[1]
        slot = (np.asarray(labels, np.int64)[:, None] * d + np.arange(d)) * 256 + x
        w = None if weights is None else np.repeat(np.asarray(weights, np.float64), d)
        hist = np.bincount(slot.ravel(), weights=w, minlength=n_clusters * d * 256).reshape(n_clusters * d, 256)
        counts = hist @ _BYTE_BITS
        return np.rint(counts).astype(np.int32).reshape(n_clusters, d * 8), sizes
    if kind is DescriptorKind.BINARY:
        rows, dtype = (unpacked_bits(x) if bits is None else bits), np.int32
    else:
        rows, dtype = x, np.float64
    data = np.ones(len(x), dtype) if weights is None else np.asarray(weights, dtype)
    onehot = csr_matrix((data, (labels, np.arange(len(x)))), shape=(n_clusters, len(x)))
    return np.asarray(onehot @ rows, dtype), sizes


def centres_from_sums(kind: DescriptorKind, sums: np.ndarray, sizes: np.ndarray, dtype) -> np.ndarray:
    """Majority bits (ties -> 1, as DBoW2) or means; empty clusters get a zero centre."""
    if kind is DescriptorKind.BINARY:
        return np.packbits((2 * sums >= sizes[:, None]) & (sizes > 0)[:, None], axis=1)
    return (sums / np.maximum(sizes, 1)[:, None]).astype(dtype)


def centres(kind: DescriptorKind, x: np.ndarray, labels: np.ndarray, n_clusters: int,
            bits: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cluster centres (n_clusters, D) and cluster sizes: majority bits (ties -> 1, as DBoW2) or the mean. Empty
    clusters get a zero centre and size 0. Pass `bits` = unpacked_bits(x) when calling repeatedly on the same x."""
    sums, sizes = cluster_sums(kind, x, labels, n_clusters, bits)
    return centres_from_sums(kind, sums, sizes, x.dtype), sizes


def unpacked_bits(x: np.ndarray) -> np.ndarray:
    """(n, 8 D) uint8 0/1 matrix of packed bit rows."""
    return np.unpackbits(x, axis=1)
