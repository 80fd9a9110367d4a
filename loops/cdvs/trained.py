"""The small parameter file learned offline (`python -m loops.cdvs.training`): bit priority order of the local
descriptor bits, relevance tables for feature selection, the binary codebook and projection of the global
descriptor, the global-score weight table and the per-mode pair decision thresholds.

The file is `loops/data/cdvs_trained.npz` (~60 kB); its provenance (training images, seed, command) is stored in it.
"""
from __future__ import annotations

import functools
import json
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from loops.errors import LoopsError
from odometry.shared.atomic_io import atomic_path

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
DEFAULT_TRAINED = DATA_DIR / "cdvs_trained.npz"
N_BITS = 256          # ORB descriptor length
GLOBAL_BITS = 32      # bits per codebook cluster in the global descriptor


@dataclass(frozen=True)
class TrainedParams:
    bit_order: np.ndarray        # (256,) descriptor bit indices, most useful first
    resp_edges: np.ndarray       # (R-1,) inner bin edges of log(response / median response)
    resp_p: np.ndarray           # (R,) relevance factor per response bin
    octave_p: np.ndarray         # (L,) relevance factor per pyramid level
    radius_edges: np.ndarray     # (Q-1,) inner bin edges of distance-from-centre / half-diagonal
    radius_p: np.ndarray         # (Q,) P(matched | radius, visible in both views): no centre preference
    radius_p_central: np.ndarray  # (Q,) P(matched | radius) including visibility: prefers the image centre
    codebook: np.ndarray         # (K, 32) uint8 binary centroids
    cluster_mean: np.ndarray     # (K, 256) float32 mean bit value per cluster (residual reference)
    projection: np.ndarray       # (256, 32) float32 residual projection (PCA)
    global_weights: np.ndarray   # (33,) float32 T[h]: contribution of a common cluster at Hamming distance h
    local_threshold: np.ndarray  # (6,) pair decision: local score threshold per mode
    global_threshold: np.ndarray  # (6,) pair decision: global score threshold per mode
    provenance: dict
    params_id: int               # 16-bit id of these parameters, written into every descriptor

    @property
    def n_clusters(self) -> int:
        return int(self.codebook.shape[0])


ARRAY_FIELDS = ("bit_order", "resp_edges", "resp_p", "octave_p", "radius_edges", "radius_p", "radius_p_central",
                "codebook",
                "cluster_mean", "projection", "global_weights", "local_threshold", "global_threshold")
# Fields that change what is written into a descriptor: their hash is the params id.
_ID_FIELDS = ("bit_order", "codebook", "cluster_mean", "projection")


def compute_params_id(arrays: dict) -> int:
    crc = 0
    for name in _ID_FIELDS:
        crc = zlib.crc32(np.ascontiguousarray(arrays[name]).tobytes(), crc)
    return (crc ^ (crc >> 16)) & 0xFFFF


def save_trained(path: str | Path, arrays: dict, provenance: dict) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, provenance=np.array(json.dumps(provenance)), **{k: arrays[k] for k in ARRAY_FIELDS})


def load_trained(path: str | Path | None = None) -> TrainedParams:
    """Load a trained parameter file (default: the shipped one). Cached per path."""
    return _load_cached(str(Path(path).resolve()) if path is not None else str(DEFAULT_TRAINED))


def forget_loaded() -> None:
    """Drop the cached parameter files (after writing a new one at a path already loaded)."""
    _load_cached.cache_clear()


@functools.lru_cache(maxsize=8)
def _load_cached(path: str) -> TrainedParams:
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"{p}: trained descriptor parameters not found (run python -m loops.cdvs.training)")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: np.array(z[k]) for k in ARRAY_FIELDS}
            provenance = json.loads(str(z["provenance"]))
    except (KeyError, ValueError, OSError, zlib.error) as exc:
        raise LoopsError(f"{p}: not a valid trained descriptor parameter file ({exc})") from exc
    arrays["codebook"] = arrays["codebook"].astype(np.uint8)
    arrays["bit_order"] = arrays["bit_order"].astype(np.int64)
    for k in ("cluster_mean", "projection", "global_weights"):
        arrays[k] = arrays[k].astype(np.float32)
    if sorted(arrays["bit_order"].tolist()) != list(range(N_BITS)):
        raise LoopsError(f"{p}: bit_order is not a permutation of 0..{N_BITS - 1}")
    if arrays["projection"].shape != (N_BITS, GLOBAL_BITS) or arrays["codebook"].shape[1] != N_BITS // 8:
        raise LoopsError(f"{p}: codebook/projection shapes do not match a {N_BITS}-bit descriptor")
    for a in arrays.values():
        a.setflags(write=False)
    return TrainedParams(**arrays, provenance=provenance, params_id=compute_params_id(arrays))
