"""Pair files of 1D SURF horizons: PAIRS.csv (a, b, row_a, row_b, other columns kept) in, SCORES.csv (the input
columns + score, score_ransac, b_s, b_d) out, and the labelled scores an ROC is computed from.

A horizon is a row number, or LEFT:RIGHT for a horizon line crossing the left image edge at row LEFT and the right
edge at row RIGHT (a rolled camera). Relative image paths in a pair file are relative to the file's folder. Errors
name the file, the line and the field.
"""
from __future__ import annotations

import csv
import math
from collections import OrderedDict
from pathlib import Path

import cv2
import numpy as np

from loops.horizon.params import HorizonParams
from loops.horizon.signal import HorizonError, HorizonLine
from loops.horizon.views import HorizonView, extract_view, match_views
from odometry.shared.atomic_io import atomic_path

PAIRS_COLUMNS = ("a", "b", "row_a", "row_b")
SCORE_COLUMNS = ("score", "score_ransac", "b_s", "b_d")


def parse_horizon(text: str, where: str) -> float | HorizonLine:
    """'183' -> 183.0 (a level horizon row); '180:186' -> HorizonLine(180, 186). HorizonError names `where`."""
    parts = str(text).strip().split(":")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise HorizonError(f"{where}: {text!r} is not a horizon row (a number, or LEFT:RIGHT)") from None
    if len(vals) not in (1, 2) or not all(math.isfinite(v) for v in vals):
        raise HorizonError(f"{where}: {text!r} is not a horizon row (a number, or LEFT:RIGHT)")
    return vals[0] if len(vals) == 1 else HorizonLine(vals[0], vals[1])


def read_gray_image(path: Path) -> np.ndarray:
    """An image file as 8-bit grey; FileNotFoundError / OSError name the file."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: image not found")
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise OSError(f"{path}: cannot decode the image")
    return img


def extract_file_features(path: Path, horizon, params: HorizonParams) -> HorizonView:
    """1D SURF features of the horizon of an image file (packed bands on the packed path; errors name the file)."""
    img = read_gray_image(path)
    try:
        return extract_view(img, horizon, params)
    except HorizonError as exc:
        raise HorizonError(f"{path}: {exc}") from None


class FeatureCache:
    """Features by (image, horizon), bounded so a long pair list keeps bounded memory."""

    def __init__(self, params: HorizonParams, size: int = 2048):
        self.params, self.size, self.data = params, size, OrderedDict()

    def get(self, path: Path, horizon) -> HorizonView:
        key = (str(path), repr(horizon))
        if key in self.data:
            self.data.move_to_end(key)
            return self.data[key]
        f = extract_file_features(path, horizon, self.params)
        self.data[key] = f
        if len(self.data) > self.size:
            self.data.popitem(last=False)
        return f


def read_pairs_csv(path: Path) -> tuple[list[str], list[dict]]:
    """(header, rows) of a PAIRS.csv; each row also holds its parsed horizons under "_row_a" / "_row_b" and its
    line number under "_line"."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: pairs file not found")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        missing = [c for c in PAIRS_COLUMNS if c not in header]
        if missing:
            raise HorizonError(f"{path} line 1: missing column(s) {', '.join(missing)} (need {','.join(PAIRS_COLUMNS)})")
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if None in row or any(row[c] is None for c in header):
                raise HorizonError(f"{path} line {line_no}: expected {len(header)} fields")
            for c in ("a", "b"):
                if not row[c].strip():
                    raise HorizonError(f"{path} line {line_no}, field {c}: empty image path")
            for c in ("row_a", "row_b"):
                row[f"_{c}"] = parse_horizon(row[c], f"{path} line {line_no}, field {c}")
            row["_line"] = line_no
            rows.append(row)
    return header, rows


def score_pairs_file(pairs_csv: Path, out_csv: Path, params: HorizonParams) -> list[dict]:
    """Score every pair of PAIRS.csv (b is the test horizon, a the stored one: x_b = b_s * x_a + b_d) and write
    SCORES.csv atomically: the input columns, then score, score_ransac, b_s, b_d. Returns the output rows."""
    pairs_csv, out_csv = Path(pairs_csv), Path(out_csv)
    header, rows = read_pairs_csv(pairs_csv)
    clash = [c for c in SCORE_COLUMNS if c in header]
    if clash:
        raise HorizonError(f"{pairs_csv} line 1: column(s) {', '.join(clash)} would be overwritten by the scores")
    base = pairs_csv.parent
    cache = FeatureCache(params)
    # The pairs of one test view are scored in one call (on the packed path that is what makes it cheap).
    groups: dict[tuple[str, str], list[int]] = OrderedDict()
    for i, row in enumerate(rows):
        groups.setdefault((row["b"], repr(row["_row_b"])), []).append(i)
    results: list = [None] * len(rows)
    for idx in groups.values():
        first = cache.get(base / rows[idx[0]]["a"], rows[idx[0]]["_row_a"])    # a, then b: the file's order
        fb = cache.get(base / rows[idx[0]]["b"], rows[idx[0]]["_row_b"])
        stored = [first] + [cache.get(base / rows[i]["a"], rows[i]["_row_a"]) for i in idx[1:]]
        for i, r in zip(idx, match_views(fb, stored, params)):
            results[i] = r
    out_rows = []
    for row, r in zip(rows, results):
        out = {c: row[c] for c in header}
        out.update(score=r.score, score_ransac=r.score_ransac, b_s=r.b_s, b_d=r.b_d)
        out_rows.append(out)
    with atomic_path(out_csv) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*header, *SCORE_COLUMNS])
        for o in out_rows:
            w.writerow([o[c] for c in header] + [f"{o['score']:.6g}", f"{o['score_ransac']:.6g}",
                                                f"{o['b_s']:.6g}", f"{o['b_d']:.6g}"])
    return out_rows


def read_scored_pairs(path: Path, label_column: str = "label") -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(labels as bool, {"score": ..., "score_ransac": ...}) of a SCORES.csv with a 0/1 label column."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: scores file not found")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        need = [label_column, *SCORE_COLUMNS[:2]]
        missing = [c for c in need if c not in header]
        if missing:
            raise HorizonError(f"{path} line 1: missing column(s) {', '.join(missing)}")
        labels, cols = [], {c: [] for c in SCORE_COLUMNS[:2]}
        for line_no, row in enumerate(reader, start=2):
            labels.append(_label(row[label_column], f"{path} line {line_no}, field {label_column}"))
            for c in cols:
                try:
                    cols[c].append(float(row[c]))
                except (TypeError, ValueError):
                    raise HorizonError(f"{path} line {line_no}, field {c}: {row[c]!r} is not a number") from None
    return np.array(labels, bool), {c: np.array(v) for c, v in cols.items()}


def _label(text, where: str) -> int:
    try:
        lab = int(float(text))
    except (TypeError, ValueError):
        raise HorizonError(f"{where}: {text!r} is not 0 or 1") from None
    if lab not in (0, 1):
        raise HorizonError(f"{where}: {lab} is not 0 or 1")
    return lab
