"""Descriptor kinds, kept apart from the vocabulary tree (as in DBoW2) so one tree serves every descriptor.

BINARY: packed bit strings (uint8 rows, e.g. 32 bytes = 256 bits), Hamming distance, majority-bit centres.
FLOAT:  real vectors (float32 rows), Euclidean distance, mean centres.
"""
from __future__ import annotations

import enum

import numpy as np


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


def _words(a: np.ndarray) -> np.ndarray:
    """Packed bits seen as uint64 words when the row length allows it: 8x fewer popcounts."""
    if a.shape[-1] % 8 == 0 and a.flags.c_contiguous:
        return a.view(np.uint64)
    return a


def distances(kind: DescriptorKind, x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distances between rows of x (n, D) and of c (m, D) -> (n, m) float32 (Hamming bits, or Euclidean)."""
    if kind is DescriptorKind.BINARY:
        xw, cw = _words(np.ascontiguousarray(x)), _words(np.ascontiguousarray(c))
        return np.bitwise_count(xw[:, None, :] ^ cw[None, :, :]).sum(axis=2, dtype=np.int32).astype(np.float32)
    d2 = (x * x).sum(1)[:, None] - 2.0 * (x @ c.T) + (c * c).sum(1)[None, :]
    return np.sqrt(np.maximum(d2, 0.0)).astype(np.float32)


def batched_distances(kind: DescriptorKind, x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distances from each row x[i] (n, D) to its own candidates c[i] (n, m, D) -> (n, m)."""
    if kind is DescriptorKind.BINARY:
        xw, cw = _words(np.ascontiguousarray(x)), _words(np.ascontiguousarray(c))
        return np.bitwise_count(xw[:, None, :] ^ cw).sum(axis=2, dtype=np.int32).astype(np.float32)
    diff = c - x[:, None, :]
    return np.sqrt(np.einsum("nmd,nmd->nm", diff, diff))


def centres(kind: DescriptorKind, x: np.ndarray, labels: np.ndarray, n_clusters: int,
            bits: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cluster centres (n_clusters, D) and cluster sizes. Empty clusters get a zero centre and size 0.

    BINARY centres take the majority bit (ties -> 1, as DBoW2); pass `bits` = unpacked_bits(x) when calling
    repeatedly on the same x. Rows are sorted by cluster once and each cluster's slice summed: no BLAS (whose
    threads stall on a loaded machine) and no slow scatter-adds.
    """
    order = np.argsort(labels, kind="stable")
    sizes = np.bincount(labels, minlength=n_clusters)
    bounds = np.concatenate(([0], np.cumsum(sizes)))
    if kind is DescriptorKind.BINARY:
        b = (unpacked_bits(x) if bits is None else bits)[order]
        sums = np.stack([b[bounds[c]:bounds[c + 1]].sum(axis=0, dtype=np.int32) for c in range(n_clusters)])
        majority = (2 * sums >= sizes[:, None]) & (sizes > 0)[:, None]
        return np.packbits(majority, axis=1), sizes
    xs = x[order]
    sums = np.stack([xs[bounds[c]:bounds[c + 1]].sum(axis=0, dtype=np.float64) for c in range(n_clusters)])
    return (sums / np.maximum(sizes, 1)[:, None]).astype(np.float32), sizes


def unpacked_bits(x: np.ndarray) -> np.ndarray:
    """(n, 8 D) uint8 0/1 matrix of packed bit rows."""
    return np.unpackbits(x, axis=1)
