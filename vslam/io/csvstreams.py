"""Strict readers for the sequence's CSV streams: exact headers, finite numbers, increasing timestamps.

Errors name the file, the 1-based line and the column.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from vslam.errors import CsvFormatError, MissingFileError, NonFiniteValueError, TimestampOrderError, UnknownColumnError


def _header(path: Path, row: list[str], expected: tuple[str, ...]) -> list[int]:
    """Column positions of `expected` in the header row; unknown or missing columns are errors."""
    cols = [c.strip() for c in row]
    for c in cols:
        if c not in expected:
            raise UnknownColumnError(path, f"unknown column (expected header '{','.join(expected)}')", line=1, field=c)
    for c in expected:
        if c not in cols:
            raise CsvFormatError(path, f"missing column (expected header '{','.join(expected)}')", line=1, field=c)
    if len(set(cols)) != len(cols):
        raise CsvFormatError(path, "duplicate column in header", line=1)
    return [cols.index(c) for c in expected]


def read_csv_columns(path: Path, expected: tuple[str, ...], text_columns: tuple[str, ...] = ()) -> dict:
    """Read a CSV with header `expected`. Numeric columns become float arrays; `text_columns` stay strings.
    The first column is a timestamp and must strictly increase."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(path, "file not found")
    with open(path, newline="", encoding="utf-8") as f:
        reader = csv.reader(f)
        try:
            head = next(reader)
        except StopIteration:
            raise CsvFormatError(path, f"empty file (expected header '{','.join(expected)}')", line=1) from None
        pos = _header(path, head, expected)
        values: dict[str, list] = {c: [] for c in expected}
        last_t = -math.inf
        for lineno, row in enumerate(reader, 2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != len(head):
                raise CsvFormatError(path, f"expected {len(head)} values, got {len(row)}", line=lineno)
            for c, p in zip(expected, pos):
                s = row[p].strip()
                if c in text_columns:
                    if not s:
                        raise CsvFormatError(path, "empty value", line=lineno, field=c)
                    values[c].append(s)
                    continue
                try:
                    v = float(s)
                except ValueError:
                    raise CsvFormatError(path, f"not a number: {s!r}", line=lineno, field=c) from None
                if not math.isfinite(v):
                    raise NonFiniteValueError(path, f"{s} is not a finite number", line=lineno, field=c)
                values[c].append(v)
            t = values[expected[0]][-1]
            if t <= last_t:
                raise TimestampOrderError(path, f"timestamp {t!r} does not increase (previous {last_t!r})",
                                          line=lineno, field=expected[0])
            last_t = t
    return {c: (v if c in text_columns else np.asarray(v, dtype=float)) for c, v in values.items()}


def format_csv(header: tuple[str, ...], columns: list) -> str:
    """CSV text with `header`; float columns printed with full precision, text columns as given."""
    n = len(columns[0]) if columns else 0
    lines = [",".join(header)]
    fmt = []
    for col in columns:
        if isinstance(col, np.ndarray) and col.dtype.kind == "f":
            fmt.append([repr(float(x)) for x in col])
        else:
            fmt.append([str(x) for x in col])
    lines += [",".join(f[i] for f in fmt) for i in range(n)]
    return "\n".join(lines) + "\n"
