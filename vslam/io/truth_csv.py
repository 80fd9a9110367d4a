"""Place-recognition ground truth as CSV: header `query,key`, one row per (query image, true key image) by name,
several rows per query allowed."""
from __future__ import annotations

import csv
from pathlib import Path
from typing import Sequence

from odometry.shared.atomic_io import atomic_write_text
from vslam.errors import VslamError


def _name_index(names: Sequence[str]) -> dict[str, int]:
    """Index by full relative name, and by file name where that is not taken."""
    index = {n: i for i, n in enumerate(names)}
    for i, n in enumerate(names):
        index.setdefault(Path(n).name, i)
    return index


def read_truth(path: str | Path, query_names: Sequence[str], key_names: Sequence[str]) -> dict[str, list[int]]:
    """TRUTH.csv -> {query name: [key indices]}. Names match a full relative name or a file name; unknown names
    are errors naming the line."""
    path = Path(path)
    q_index = _name_index(query_names)
    k_index = _name_index(key_names)
    truth: dict[str, list[int]] = {}
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None or [h.strip() for h in header[:2]] != ["query", "key"]:
            raise VslamError(f"{path}: line 1: header must be 'query,key'")
        for line, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) < 2:
                raise VslamError(f"{path}: line {line}: expected 2 fields 'query,key', got {len(row)}")
            q, k = row[0].strip(), row[1].strip()
            if q not in q_index:
                raise VslamError(f"{path}: line {line}: field 'query': no query image named {q!r}")
            if k not in k_index:
                raise VslamError(f"{path}: line {line}: field 'key': no key image named {k!r}")
            truth.setdefault(query_names[q_index[q]], []).append(k_index[k])
    return truth


def write_truth(path: str | Path, truth: dict[str, list[int]], key_names: Sequence[str]) -> None:
    """{query name: [key indices]} as TRUTH.csv, written atomically."""
    rows = ["query,key"] + [f"{q},{key_names[k]}" for q, ks in truth.items() for k in ks]
    atomic_write_text(path, "\n".join(rows) + "\n")
