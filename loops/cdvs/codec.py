"""Versioned binary codec of the compact descriptor, with the mode budget enforced by the encoder.

Layout (big-endian), version 1:

    header (24 B): magic "CD", version, mode, original w, h, processed w, h, number of local features,
                   bytes per local descriptor, coordinate block, Rice parameter, codebook size K, visited clusters,
                   flags, params id (16-bit hash of the trained parameters), unary stream length
    global:        K-bit visited mask, then 32 bits per visited cluster
    coordinates:   block indices (processed pixels / block) in raster order, sorted, delta + Rice coded as a unary
                   stream and a fixed-width remainder stream
    locals:        one descriptor per feature in the same spatial order, `desc_bits` ORB bits in trained priority order
    CRC32 (4 B) of everything before it

Every length is derived from header fields and checked against the bytes actually present before anything is
allocated, so a truncated, corrupt or foreign byte string raises DescriptorDecodeError and never allocates more
than a small multiple of its own size.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

from loops.cdvs.bitcode import best_rice_k, rice_cost, rice_decode, rice_encode
from loops.cdvs.extract import Features, extract_features
from loops.cdvs.global_desc import cluster_signatures, select_clusters
from loops.cdvs.params import BUDGETS, MODES, CdvsParams
from loops.cdvs.trained import GLOBAL_BITS, N_BITS, TrainedParams, load_trained
from loops.errors import LoopsError

MAGIC = b"CD"
VERSION = 1
_HEADER = struct.Struct(">2sBBHHHHHBBBBBBHH")
HEADER_SIZE = _HEADER.size
CRC_SIZE = 4
MAX_RICE_K = 24
# Upper bound on local features in one descriptor. The encoder never writes more (the modes keep at most 300), and
# the decoder refuses more: all-pairs matching is quadratic in this number, so a crafted header must not set it.
MAX_LOCAL = 2048


class DescriptorDecodeError(LoopsError):
    """A byte string is not a valid compact descriptor (truncated, corrupt, foreign or unsupported)."""


@dataclass(frozen=True, eq=False)
class Descriptor:
    """A decoded compact descriptor."""

    mode: int
    image_size: tuple[int, int]       # (width, height) of the original image
    proc_size: tuple[int, int]        # (width, height) of the processed (resized) image
    keypoints: np.ndarray             # (N, 2) float32 keypoints in pixels of the original image
    xy: np.ndarray                    # (N, 2) float32 keypoints in processed-image pixels (used for geometry)
    local: np.ndarray                 # (N, desc_bits / 8) uint8 local descriptors, bits in priority order
    global_visited: np.ndarray        # (K,) bool
    global_bits: np.ndarray           # (K,) uint32, zero where not visited
    params_id: int                    # which trained parameters produced it
    nbytes: int                       # serialised size

    @property
    def n_local(self) -> int:
        return int(self.local.shape[0])

    @property
    def desc_bits(self) -> int:
        return int(self.local.shape[1]) * 8


def _bits_to_priority(desc: np.ndarray, order: np.ndarray, n_bits: int) -> np.ndarray:
    bits = np.unpackbits(desc, axis=1)[:, order[:n_bits]]
    return np.packbits(bits, axis=1)


def _block_indices(xy: np.ndarray, proc_size: tuple[int, int], block: int) -> np.ndarray:
    w, h = proc_size
    bw = -(-w // block)
    bx = np.clip(np.floor(xy[:, 0] / block), 0, bw - 1).astype(np.int64)
    by = np.clip(np.floor(xy[:, 1] / block), 0, -(-h // block) - 1).astype(np.int64)
    return by * bw + bx


def _coord_bytes(idx_sorted: np.ndarray) -> tuple[int, int]:
    gaps = np.diff(idx_sorted, prepend=0)
    k = best_rice_k(gaps, MAX_RICE_K)
    n = len(gaps)
    unary_bits = rice_cost(gaps, k) - n * k
    return -(-unary_bits // 8) + -(-(n * k) // 8), k


def encode_features(feats: Features, params: CdvsParams, trained: TrainedParams,
                    signatures: tuple[np.ndarray, np.ndarray] | None = None) -> bytes:
    """Serialise already extracted features under the mode's byte budget (never exceeded). `signatures`
    (from global_desc.cluster_signatures) may be passed to share the global aggregation across modes."""
    mp = params.mode
    if mp.desc_bits % 8 or not 8 <= mp.desc_bits <= N_BITS:
        raise ValueError(f"desc_bits must be a multiple of 8 in 8..{N_BITS}, got {mp.desc_bits}")
    k_clusters = trained.n_clusters
    base = HEADER_SIZE + CRC_SIZE + -(-k_clusters // 8)
    max_clusters = max(0, min(mp.global_clusters, (mp.budget - base) // (GLOBAL_BITS // 8)))
    if signatures is None:
        signatures = cluster_signatures(feats.desc, trained)
    visited, gbits = select_clusters(*signatures, max_clusters)
    n_vis = int(visited.sum())
    fixed = base + n_vis * GLOBAL_BITS // 8
    dbytes = mp.desc_bits // 8
    avail = mp.budget - fixed
    blocks = _block_indices(feats.xy, feats.proc_size, mp.coord_block)
    n_max = min(len(blocks), mp.max_local, MAX_LOCAL, avail // dbytes)

    def cost(n: int) -> int:
        return _coord_bytes(np.sort(blocks[:n]))[0] + n * dbytes if n else 0

    lo, hi = 0, n_max                       # largest n with cost(n) <= avail (cost is near-monotone)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if cost(mid) <= avail:
            lo = mid
        else:
            hi = mid - 1
    n = lo
    while n > 0 and cost(n) > avail:        # guarantee, whatever the shape of cost()
        n -= 1
    order = np.argsort(blocks[:n], kind="stable")
    idx = blocks[:n][order]
    gaps = np.diff(idx, prepend=0)
    rk = best_rice_k(gaps, MAX_RICE_K) if n else 0
    unary, rem = rice_encode(gaps, rk)
    local = _bits_to_priority(feats.desc[:n][order], trained.bit_order, mp.desc_bits) if n else b""
    mask = np.packbits(visited).tobytes()
    gb = gbits[visited].astype(">u4").tobytes()
    ow, oh = feats.orig_size
    pw, ph = feats.proc_size
    header = _HEADER.pack(MAGIC, VERSION, mp.mode, ow, oh, pw, ph, n, dbytes, mp.coord_block, rk, k_clusters,
                          n_vis, 0, trained.params_id, len(unary))
    body = b"".join([header, mask, gb, unary, rem, bytes(local)])
    out = body + struct.pack(">I", zlib.crc32(body))
    assert len(out) <= mp.budget, (len(out), mp.budget)
    return out


def encode(image: np.ndarray, mode: int, params: CdvsParams | None = None,
           trained: TrainedParams | None = None) -> bytes:
    """Image (gray or BGR) -> compact descriptor bytes of at most the mode's budget."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    params = params or CdvsParams.for_mode(mode)
    if params.mode.mode != mode:
        raise ValueError(f"params are for mode {params.mode.mode}, not {mode}")
    trained = trained or load_trained()
    return encode_features(extract_features(image, params.extraction, trained), params, trained)


def extract(image: np.ndarray, mode: int, params: CdvsParams | None = None,
            trained: TrainedParams | None = None) -> Descriptor:
    """encode + decode: the descriptor exactly as a receiver of the bytes sees it."""
    return decode(encode(image, mode, params, trained), trained)


def encode_all_modes(image: np.ndarray, modes=MODES, params: dict[int, CdvsParams] | None = None,
                     trained: TrainedParams | None = None) -> dict[int, bytes]:
    """One extraction, every requested mode encoded (the extraction does not depend on the mode)."""
    trained = trained or load_trained()
    params = params or {m: CdvsParams.for_mode(m) for m in modes}
    feats = extract_features(image, params[modes[0]].extraction, trained)
    sig = cluster_signatures(feats.desc, trained)
    return {m: encode_features(feats, params[m], trained, sig) for m in modes}


def decode(data: bytes, trained: TrainedParams | None = None) -> Descriptor:
    """Bytes -> Descriptor; raises DescriptorDecodeError naming what is wrong.

    Every header field is checked against the format and, for a descriptor made with the `trained` parameters
    (default: the shipped ones; same params id), against them (codebook size K), so that a decoded descriptor can
    be matched without further checks. A descriptor of other trained parameters decodes too; `match` refuses to
    compare it with one of different parameters."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise DescriptorDecodeError(f"expected bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) < HEADER_SIZE + CRC_SIZE:
        raise DescriptorDecodeError(f"truncated: {len(data)} bytes, a descriptor has at least "
                                    f"{HEADER_SIZE + CRC_SIZE}")
    (magic, version, mode, ow, oh, pw, ph, n, dbytes, block, rk, k_clusters, n_vis, flags, params_id,
     unary_len) = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise DescriptorDecodeError(f"not a compact descriptor (magic {magic!r}, expected {MAGIC!r})")
    if version != VERSION:
        raise DescriptorDecodeError(f"unsupported descriptor version {version} (this decoder reads {VERSION})")
    mask_len = -(-k_clusters // 8)
    rem_len = -(-(n * rk) // 8)
    expected = HEADER_SIZE + mask_len + n_vis * 4 + unary_len + rem_len + n * dbytes + CRC_SIZE
    if len(data) < expected:
        raise DescriptorDecodeError(f"truncated: {len(data)} bytes, the header announces {expected}")
    if len(data) > expected:
        raise DescriptorDecodeError(f"{len(data) - expected} unexpected trailing bytes after the descriptor")
    (crc,) = struct.unpack_from(">I", data, expected - CRC_SIZE)
    if zlib.crc32(data[: expected - CRC_SIZE]) != crc:
        raise DescriptorDecodeError("corrupt descriptor: CRC32 mismatch")
    # checksum passed: the remaining checks catch encoder bugs and hand-crafted input
    if mode not in MODES:
        raise DescriptorDecodeError(f"invalid mode {mode}")
    if len(data) > BUDGETS[mode]:
        raise DescriptorDecodeError(f"{len(data)} bytes exceed the mode {mode} budget of {BUDGETS[mode]}")
    if min(ow, oh, pw, ph) == 0 or pw > ow or ph > oh:
        raise DescriptorDecodeError(f"invalid image sizes {ow}x{oh} -> {pw}x{ph}")
    if not 1 <= dbytes <= N_BITS // 8:
        raise DescriptorDecodeError(f"invalid local descriptor length {dbytes} bytes (1..{N_BITS // 8})")
    if n > MAX_LOCAL:
        raise DescriptorDecodeError(f"{n} local features, at most {MAX_LOCAL} are allowed")
    if k_clusters == 0:
        raise DescriptorDecodeError("codebook size K is 0")
    trained = trained or load_trained()
    if params_id == trained.params_id and k_clusters != trained.n_clusters:
        raise DescriptorDecodeError(f"codebook size K = {k_clusters} in the header, the trained parameters "
                                    f"{params_id:#06x} have K = {trained.n_clusters}")
    if block == 0 or rk > MAX_RICE_K or flags != 0:
        raise DescriptorDecodeError(f"invalid coordinate coding (block {block}, rice {rk}, flags {flags})")
    if n_vis > k_clusters:
        raise DescriptorDecodeError(f"{n_vis} visited clusters out of {k_clusters}")
    pos = HEADER_SIZE
    visited = np.unpackbits(np.frombuffer(data, np.uint8, mask_len, pos))[:k_clusters].astype(bool)
    pos += mask_len
    if int(visited.sum()) != n_vis:
        raise DescriptorDecodeError(f"visited mask has {int(visited.sum())} clusters, header says {n_vis}")
    gbits = np.zeros(k_clusters, dtype=np.uint32)
    gbits[visited] = np.frombuffer(data, ">u4", n_vis, pos)
    pos += n_vis * 4
    try:
        gaps = rice_decode(data[pos: pos + unary_len], data[pos + unary_len: pos + unary_len + rem_len], n, rk)
    except ValueError as exc:
        raise DescriptorDecodeError(f"invalid coordinates: {exc}") from None
    pos += unary_len + rem_len
    idx = np.cumsum(gaps)
    bw, bh = -(-pw // block), -(-ph // block)
    if n and idx[-1] >= bw * bh:
        raise DescriptorDecodeError(f"coordinate block {int(idx[-1])} outside the {bw}x{bh} grid")
    xy = np.column_stack([(idx % bw) * block + (block - 1) / 2.0, (idx // bw) * block + (block - 1) / 2.0])
    xy = np.minimum(xy, [pw - 1, ph - 1]).astype(np.float32)
    local = np.frombuffer(data, np.uint8, n * dbytes, pos).reshape(n, dbytes).copy()
    sx, sy = ow / pw, oh / ph
    kp = np.column_stack([(xy[:, 0] + 0.5) * sx - 0.5, (xy[:, 1] + 0.5) * sy - 0.5]).astype(np.float32)
    return Descriptor(mode=mode, image_size=(ow, oh), proc_size=(pw, ph), keypoints=kp, xy=xy, local=local,
                      global_visited=visited, global_bits=gbits, params_id=params_id, nbytes=len(data))
