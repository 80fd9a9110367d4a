"""One contiguous binary file of named numpy arrays plus a JSON header: how vocabularies and memories are stored.

Layout (little endian):
    8 bytes   magic b"VSLMVOC\\0"
    4 bytes   format version (uint32)
    4 bytes   header length H (uint32)
    H bytes   JSON header: {"meta": {...}, "crc32": int, "arrays": [{"name", "dtype", "shape", "offset"}, ...]}
    padding   to a multiple of 64 bytes
    data      the arrays back to back, each starting on a 64-byte boundary (offsets relative to the data start)

Loading reads the file once and wraps the arrays with np.frombuffer (O(n), no per-node allocation), which is what
DBoW2 users miss: text vocabularies there take minutes to hours to load.
"""
from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np

from loops.errors import LoopsError
from odometry.shared.atomic_io import atomic_write_bytes

MAGIC = b"VSLMVOC\0"
VERSION = 1
_ALIGN = 64


class VocabFileError(LoopsError):
    """A vocabulary / memory file that is not ours, is truncated, or is corrupted."""


def _pad(n: int) -> int:
    return (-n) % _ALIGN


def pack_arrays(meta: dict, arrays: dict[str, np.ndarray]) -> bytes:
    table, chunks, offset = [], [], 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        if a.dtype.byteorder == ">":
            a = a.astype(a.dtype.newbyteorder("<"))
        table.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": offset})
        raw = a.tobytes()
        chunks += [raw, b"\0" * _pad(len(raw))]
        offset += len(raw) + _pad(len(raw))
    data = b"".join(chunks)
    header = json.dumps({"meta": meta, "crc32": zlib.crc32(data), "arrays": table}).encode()
    head = MAGIC + struct.pack("<II", VERSION, len(header)) + header
    return head + b"\0" * _pad(len(head)) + data


def unpack_arrays(buf: bytes, source: str = "<bytes>") -> tuple[dict, dict[str, np.ndarray]]:
    if len(buf) < 16 or buf[:8] != MAGIC:
        raise VocabFileError(f"{source}: not a vslam vocabulary/memory file (bad magic)")
    version, hlen = struct.unpack_from("<II", buf, 8)
    if version != VERSION:
        raise VocabFileError(f"{source}: file format version {version}, this vslam reads version {VERSION}")
    if 16 + hlen > len(buf):
        raise VocabFileError(f"{source}: truncated header")
    try:
        header = json.loads(buf[16:16 + hlen].decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise VocabFileError(f"{source}: corrupted header ({exc})") from None
    start = 16 + hlen + _pad(16 + hlen)
    data = memoryview(buf)[start:]
    if zlib.crc32(data) != header.get("crc32"):
        raise VocabFileError(f"{source}: checksum mismatch (file truncated or corrupted)")
    # the JSON header is not under the checksum: every entry of the array table is checked before it is used
    table, meta = header.get("arrays") if isinstance(header, dict) else None, header.get("meta") if isinstance(
        header, dict) else None
    if not isinstance(table, list) or not isinstance(meta, dict):
        raise VocabFileError(f"{source}: corrupted header (no array table or meta)")
    arrays: dict[str, np.ndarray] = {}
    expected = 0     # pack_arrays lays the arrays back to back in table order, each padded to the alignment
    for i, e in enumerate(table):
        entry = _array_entry(e, i, data, source)
        name, a = next(iter(entry.items()))
        if name in arrays:
            raise VocabFileError(f"{source}: corrupted header (array entry {i}: name {name!r} appears twice)")
        if e["offset"] != expected:
            raise VocabFileError(_layout_error(source, table, i, expected))
        expected += a.nbytes + _pad(a.nbytes)
        arrays[name] = a
    if expected != len(data):
        raise VocabFileError(_layout_error(source, table, len(table), expected, len(data)))
    return meta, arrays


def _layout_error(source: str, table: list, i: int, expected: int, size: int | None = None) -> str:
    """Why the array table does not describe the data it heads. The checksum protects only the data, so the
    table's shapes, dtypes and offsets must account for every data byte: a shape or dtype changed in the header
    (say a descriptor width of 0) leaves bytes unclaimed and is caught here, before any array is used."""
    prev = table[i - 1] if i else None
    before = (f"array {prev['name']!r} (shape {prev['shape']}, dtype {prev['dtype']!r}) ends at byte {expected}"
              if prev else "the data starts at byte 0")
    if size is None:
        where = f"array entry {i} {table[i]['name']!r} has offset {table[i]['offset']}"
    else:
        where = f"the data holds {size} bytes"
    return f"{source}: corrupted header ({before} but {where}; a shape, dtype or offset in the array table is wrong)"


def _array_entry(e, i: int, data: memoryview, source: str) -> dict[str, np.ndarray]:
    bad = f"{source}: corrupted header (array entry {i}"
    if not isinstance(e, dict) or not isinstance(e.get("name"), str):
        raise VocabFileError(f"{bad}: no name)")
    shape, offset = e.get("shape"), e.get("offset")
    if not isinstance(shape, list) or not all(isinstance(d, int) and not isinstance(d, bool) and d >= 0
                                               for d in shape):
        raise VocabFileError(f"{bad} {e['name']!r}: shape must be a list of non-negative integers)")
    if not isinstance(offset, int) or isinstance(offset, bool) or offset < 0:
        raise VocabFileError(f"{bad} {e['name']!r}: offset must be a non-negative integer)")
    try:
        dt = np.dtype(e.get("dtype"))
    except (TypeError, ValueError):
        dt = None
    if dt is None or dt.kind not in "biuf" or not isinstance(e.get("dtype"), str):
        raise VocabFileError(f"{bad} {e['name']!r}: not a numeric dtype: {e.get('dtype')!r})")
    count = 1
    for d in shape:
        count *= d
    end = offset + count * dt.itemsize
    if end > len(data):
        raise VocabFileError(f"{source}: array {e['name']!r} runs past the end of the file")
    return {e["name"]: np.frombuffer(data, dtype=dt, count=count, offset=offset).reshape(shape)}


def save_arrays(path: str | Path, meta: dict, arrays: dict[str, np.ndarray]) -> None:
    atomic_write_bytes(path, pack_arrays(meta, arrays))


def load_arrays(path: str | Path) -> tuple[dict, dict[str, np.ndarray]]:
    path = Path(path)
    try:
        buf = path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such vocabulary/memory file") from None
    return unpack_arrays(buf, str(path))
