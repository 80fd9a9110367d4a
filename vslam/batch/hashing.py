"""Fingerprints that decide whether a finished sequence is redone: the hash of its input files and the hash of
the configuration it ran with.

The input hash reads every file of the sequence (SHA-256 of relative path, size and content), so a copied or
touched sequence with the same bytes keeps its hash. Reading a large sequence costs time, so a cheap stat
fingerprint (relative paths, sizes, modification times) is stored beside it: when the stat fingerprint matches the
previous run's, the previous input hash is reused without reading the files again.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

CHUNK = 1 << 20


def _files(path: Path) -> list[tuple[str, Path]]:
    if path.is_file():
        return [(path.name, path)]
    if not path.is_dir():
        return []
    out = []
    for root, dirs, files in os.walk(path):
        dirs.sort()
        for f in sorted(files):
            full = Path(root) / f
            out.append((full.relative_to(path).as_posix(), full))
    return out


def stat_fingerprint(path: str | Path, extra: tuple[str | Path, ...] = ()) -> str:
    """SHA-256 over (relative path, size, mtime in ns) of every file of the sequence and of `extra` files
    (e.g. a camera.yaml given with --camera); "missing" when the sequence does not exist."""
    path = Path(path)
    if not path.exists():
        return "missing"
    h = hashlib.sha256()
    for rel, full in _files(path) + [(str(e), Path(e)) for e in extra]:
        try:
            st = full.stat()
            h.update(f"{rel}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
        except OSError:
            h.update(f"{rel}\0missing\n".encode())
    return h.hexdigest()


def input_hash(path: str | Path, extra: tuple[str | Path, ...] = ()) -> str:
    """SHA-256 over (relative path, size, content) of every file of the sequence and of `extra` files."""
    path = Path(path)
    if not path.exists():
        return "missing"
    h = hashlib.sha256()
    for rel, full in _files(path) + [(str(e), Path(e)) for e in extra]:
        h.update(f"{rel}\0".encode())
        try:
            with open(full, "rb") as f:
                size = 0
                while chunk := f.read(CHUNK):
                    h.update(chunk)
                    size += len(chunk)
            h.update(f"\0{size}\n".encode())
        except OSError:
            h.update(b"\0missing\n")
    return h.hexdigest()


def config_hash(config_dict: dict, options: dict) -> str:
    """SHA-256 of the pipeline configuration (as `Config.to_dict`) and the run options (camera, max_frames)."""
    text = json.dumps({"config": config_dict, "options": options}, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()
