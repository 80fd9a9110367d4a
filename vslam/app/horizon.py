"""1D SURF horizon landmarks from image files: memorise, recognise, score a pair file, evaluate scored pairs
(`vslam horizon ...`).

Functions report one line per image or result through `echo` (the CLI passes `print`) and return what they made.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from loops.curves import auc, roc_curve, tpr_at_fpr
from loops.horizon import HorizonParams, LandmarkMemory, load_memory
from loops.horizon.pairs_file import (
    SCORE_COLUMNS,
    extract_file_features,
    parse_horizon,
    read_scored_pairs,
    score_pairs_file,
)
from odometry.shared.atomic_io import atomic_write_text
from vslam.errors import VslamError
from vslam.evaluation.plots import plot_roc_curves

Echo = Callable[[str], None]


def _silent(_: str) -> None:
    pass


def apply_overrides(params: HorizonParams, overrides: Sequence[str]) -> HorizonParams:
    """Apply FIELD=VALUE strings (`--set`) to a HorizonParams; values are parsed as JSON, else kept as text."""
    changes = {}
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise VslamError(f"--set expects FIELD=VALUE, got {item!r}")
        try:
            changes[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            changes[key.strip()] = value
    unknown = sorted(set(changes) - set(params.to_dict()))
    if unknown:
        raise VslamError(f"--set: unknown HorizonParams field(s): {', '.join(unknown)}")
    return params.replace(**changes)


# `vslam horizon`'s preset: the packed multi-band path. On the real pairs it scores AUC 0.864 (reporting half) and
# 0.879 (tuning half) against the paper preset's 0.759 / 0.749, and 0.969 against 0.933 on the KITTI crop bank
# (docs/horizon.md); the Python API's HorizonParams() stays the paper's method.
DEFAULT_PRESET = "fast"


def horizon_params(preset: str | None = None, overrides: Sequence[str] = ()) -> HorizonParams:
    """A HorizonParams preset (default DEFAULT_PRESET) with `--set` overrides applied."""
    return apply_overrides(HorizonParams.preset(preset or DEFAULT_PRESET), overrides)


def _image_horizons(images: Sequence[Path], row: str | None) -> list[tuple[Path, object]]:
    if row is None:
        raise VslamError("give the horizon with --row R (or LEFT:RIGHT for a tilted horizon line)")
    horizon = parse_horizon(row, "--row")
    return [(Path(p), horizon) for p in images]


def memorise(images: Sequence[Path], row: str, out: Path, names: Sequence[str] | None = None, append: bool = False,
             preset: str | None = None, overrides: Sequence[str] = (), echo: Echo = _silent) -> LandmarkMemory:
    """Store one landmark per image (named by `names`, default the file stems) in the memory file `out`; with
    `append`, add to an existing memory (whose stored parameters are then used)."""
    entries = _image_horizons(images, row)
    if append and out.exists():
        memory = load_memory(out)
        if preset is not None or overrides:
            raise VslamError("--append uses the parameters stored in the memory; drop --preset / --set")
    else:
        memory = LandmarkMemory(horizon_params(preset, overrides))
    names = names or [p.stem for p, _ in entries]
    if len(names) != len(entries):
        raise VslamError(f"--names gives {len(names)} names for {len(entries)} images")
    for name, (path, horizon) in zip(names, entries):
        feats = extract_file_features(path, horizon, memory.params)
        memory.add(name, feats, str(path), horizon)
        echo(f"{name}: {len(feats)} features from {path}")
    memory.save(out)
    return memory


def recognise(memory_path: Path, images: Sequence[Path], row: str, threshold: float | None = None,
              json_path: Path | None = None, echo: Echo = _silent) -> list[dict]:
    """Which stored landmark (if any) each image shows; one line per image, the results also as JSON."""
    memory = load_memory(memory_path)
    if len(memory) == 0:
        raise VslamError(f"{memory_path}: the memory holds no landmarks")
    out = []
    for path, horizon in _image_horizons(images, row):
        rec = memory.recognise(extract_file_features(path, horizon, memory.params), threshold)
        res = rec.result
        b_s = res.b_s if res else math.nan
        b_d = res.b_d if res else math.nan
        score_nn = res.score if res else 0.0
        verdict = f"landmark {rec.name}" if rec.name else "no landmark"
        echo(f"{path}: {verdict} (best {rec.best}: score {rec.score:.1f} NN+RANSAC, {score_nn:.1f} NN, "
             f"b_s {b_s:.3f}, b_d {b_d:.1f} px; threshold {rec.threshold:g})")
        out.append({"image": str(path), "landmark": rec.name, "best": rec.best, "score_ransac": rec.score,
                    "score": score_nn, "b_s": None if math.isnan(b_s) else b_s,     # null: no consistent line
                    "b_d": None if math.isnan(b_d) else b_d, "threshold": rec.threshold, "scores": rec.scores})
    if json_path:
        atomic_write_text(json_path, json.dumps(out, indent=2, default=float) + "\n")
    return out


def score_pairs(pairs_csv: Path, out_csv: Path, preset: str | None = None, overrides: Sequence[str] = ()
                ) -> list[dict]:
    """Score every pair of PAIRS.csv into SCORES.csv (see `loops.horizon.pairs_file.score_pairs_file`)."""
    return score_pairs_file(pairs_csv, out_csv, horizon_params(preset, overrides))


def evaluate_scores(scores_csv: Path, label_column: str = "label", max_fpr: float = 0.05, plot: Path | None = None,
                    echo: Echo = _silent) -> dict[str, float]:
    """ROC / AUC of the NN and NN+RANSAC scores of a SCORES.csv with a 0/1 label column, the best sensitivity at
    `max_fpr`, and the ROC curves as a PNG when `plot` is given. Returns the AUC per scorer."""
    y, cols = read_scored_pairs(scores_csv, label_column)
    if y.all() or not y.any():
        raise VslamError(f"{scores_csv}: need both label 1 and label 0 rows for an ROC "
                         f"({int(y.sum())} / {len(y)} are 1)")
    echo(f"{len(y)} pairs: {int(y.sum())} matched, {int((~y).sum())} unmatched")
    curves, aucs = {}, {}
    for c, name in zip(SCORE_COLUMNS[:2], ("NN", "NN+RANSAC")):
        s = np.asarray(cols[c])
        aucs[name] = a = auc(s, y)
        tpr, thr = tpr_at_fpr(s, y, max_fpr)
        curves[f"1D SURF, {name}"] = (*roc_curve(s, y)[:2], a)
        echo(f"{name:10s} AUC {a:.3f}; at <= {max_fpr:.0%} false positives: {tpr:.1%} matched, threshold {thr:.4g}")
    if plot:
        plot_roc_curves(plot, curves, f"{scores_csv.name}: {int(y.sum())} matched / {int((~y).sum())} unmatched")
        echo(f"wrote {plot}")
    return aucs
