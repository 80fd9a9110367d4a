"""`vslam horizon`: 1D SURF horizon landmarks - memorise, recognise, score pairs, evaluate.

    vslam horizon memorise IMAGES... --row R --out MEM.npz       store landmarks (one per image)
    vslam horizon recognise MEM.npz IMAGE... --row R              which stored landmark each image shows
    vslam horizon pairs PAIRS.csv --out SCORES.csv                score image pairs (columns a,b,row_a,row_b)
    vslam horizon evaluate SCORES.csv --plot ROC.png              ROC / AUC of scored pairs with a label column

A horizon is a row number, or LEFT:RIGHT for a horizon line crossing the left image edge at row LEFT and the right
edge at row RIGHT (a rolled camera). Relative image paths in a CSV are relative to the CSV's folder.
"""
from __future__ import annotations

import argparse
import csv
import json
import math
from collections import OrderedDict
from pathlib import Path

from vslam.errors import VslamError

NAME = "horizon"
HELP = "1D SURF horizon landmarks: memorise, recognise, score pairs, evaluate"
DESCRIPTION = __doc__

PAIRS_COLUMNS = ("a", "b", "row_a", "row_b")
SCORE_COLUMNS = ("score", "score_ransac", "b_s", "b_d")


def parse_horizon(text: str, where: str):
    """'183' -> 183.0 (a level horizon row); '180:186' -> HorizonLine(180, 186). ValueError names `where`."""
    from loops.horizon import HorizonLine

    parts = str(text).strip().split(":")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise VslamError(f"{where}: {text!r} is not a horizon row (a number, or LEFT:RIGHT)") from None
    if len(vals) not in (1, 2) or not all(math.isfinite(v) for v in vals):
        raise VslamError(f"{where}: {text!r} is not a horizon row (a number, or LEFT:RIGHT)")
    return vals[0] if len(vals) == 1 else HorizonLine(vals[0], vals[1])


def parse_overrides(params, overrides: list[str]):
    """Apply FIELD=VALUE strings to a HorizonParams (values parsed as JSON, else kept as text)."""
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


def _params_from_args(args: argparse.Namespace):
    from loops.horizon import HorizonParams

    return parse_overrides(HorizonParams.preset(args.preset), args.overrides)


def _read_gray(path: Path):
    import cv2

    if not path.is_file():
        raise FileNotFoundError(f"{path}: image not found")
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise OSError(f"{path}: cannot decode the image")
    return img


def _extract(path: Path, horizon, params):
    from loops.horizon import HorizonError, extract_features

    img = _read_gray(path)
    try:
        return extract_features(img, horizon, params)
    except HorizonError as exc:
        raise VslamError(f"{path}: {exc}") from None


class _FeatureCache:
    """Features by (image, horizon), bounded so a long pair list keeps bounded memory."""

    def __init__(self, params, size: int = 2048):
        self.params, self.size, self.data = params, size, OrderedDict()

    def get(self, path: Path, horizon):
        key = (str(path), repr(horizon))
        if key in self.data:
            self.data.move_to_end(key)
            return self.data[key]
        f = _extract(path, horizon, self.params)
        self.data[key] = f
        if len(self.data) > self.size:
            self.data.popitem(last=False)
        return f


def read_pairs_csv(path: Path) -> tuple[list[str], list[dict]]:
    """Rows of a PAIRS.csv (columns a, b, row_a, row_b; other columns kept). Errors name file, line, field."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: pairs file not found")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        missing = [c for c in PAIRS_COLUMNS if c not in header]
        if missing:
            raise VslamError(f"{path} line 1: missing column(s) {', '.join(missing)} (need {','.join(PAIRS_COLUMNS)})")
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if None in row or any(row[c] is None for c in header):
                raise VslamError(f"{path} line {line_no}: expected {len(header)} fields")
            for c in ("a", "b"):
                if not row[c].strip():
                    raise VslamError(f"{path} line {line_no}, field {c}: empty image path")
            for c in ("row_a", "row_b"):
                row[f"_{c}"] = parse_horizon(row[c], f"{path} line {line_no}, field {c}")
            row["_line"] = line_no
            rows.append(row)
    return header, rows


def score_pairs_file(pairs_csv: Path, out_csv: Path, params) -> list[dict]:
    """Score every pair of PAIRS.csv (b is the test horizon, a the stored one: x_b = b_s * x_a + b_d) and write
    SCORES.csv atomically: the input columns, then score, score_ransac, b_s, b_d. Returns the output rows."""
    from loops.horizon import match
    from odometry.shared.atomic_io import atomic_path

    pairs_csv, out_csv = Path(pairs_csv), Path(out_csv)
    header, rows = read_pairs_csv(pairs_csv)
    clash = [c for c in SCORE_COLUMNS if c in header]
    if clash:
        raise VslamError(f"{pairs_csv} line 1: column(s) {', '.join(clash)} would be overwritten by the scores")
    base = pairs_csv.parent
    cache = _FeatureCache(params)
    out_rows = []
    for row in rows:
        fa = cache.get(base / row["a"], row["_row_a"])
        fb = cache.get(base / row["b"], row["_row_b"])
        r = match(fb, fa, params)
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


def write_roc_png(path: Path, curves: dict[str, tuple], title: str) -> None:
    """ROC curves {name: (fpr, tpr, auc)} as a PNG, written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from odometry.shared.atomic_io import atomic_path

    fig, ax = plt.subplots(figsize=(4.8, 4.2), dpi=100)
    for name, (fpr, tpr, a) in curves.items():
        ax.plot(fpr, tpr, label=f"{name} (AUC {a:.3f})", lw=1.5)
    ax.plot([0, 1], [0, 1], ":", color="grey", lw=0.8)
    ax.set_xlabel("false positive rate (1 - specificity)")
    ax.set_ylabel("true positive rate (sensitivity)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.01)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


# --- sub-commands ---------------------------------------------------------------------------------------------

def _memorise(args: argparse.Namespace) -> int:
    from loops.horizon import LandmarkMemory, load_memory

    entries = _image_horizons(args)
    if args.append and args.out.exists():
        memory = load_memory(args.out)
        if args.preset != "paper" or args.overrides:
            raise VslamError("--append uses the parameters stored in the memory; drop --preset / --set")
    else:
        memory = LandmarkMemory(_params_from_args(args))
    names = args.names or [p.stem for p, _ in entries]
    if len(names) != len(entries):
        raise VslamError(f"--names gives {len(names)} names for {len(entries)} images")
    for name, (path, horizon) in zip(names, entries):
        feats = _extract(path, horizon, memory.params)
        memory.add(name, feats, str(path), horizon)
        print(f"{name}: {len(feats)} features from {path}")
    memory.save(args.out)
    print(f"wrote {args.out} ({len(memory)} landmarks)")
    return 0


def _image_horizons(args: argparse.Namespace) -> list[tuple[Path, object]]:
    if args.row is None:
        raise VslamError("give the horizon with --row R (or LEFT:RIGHT for a tilted horizon line)")
    horizon = parse_horizon(args.row, "--row")
    return [(Path(p), horizon) for p in args.images]


def _recognise(args: argparse.Namespace) -> int:
    from loops.horizon import load_memory

    memory = load_memory(args.memory)
    if len(memory) == 0:
        raise VslamError(f"{args.memory}: the memory holds no landmarks")
    out = []
    for path, horizon in _image_horizons(args):
        feats = _extract(path, horizon, memory.params)
        rec = memory.recognise(feats, args.threshold)
        res = rec.result
        b_s = res.b_s if res else math.nan
        b_d = res.b_d if res else math.nan
        score_nn = res.score if res else 0.0
        verdict = f"landmark {rec.name}" if rec.name else "no landmark"
        print(f"{path}: {verdict} (best {rec.best}: score {rec.score:.1f} NN+RANSAC, {score_nn:.1f} NN, "
              f"b_s {b_s:.3f}, b_d {b_d:.1f} px; threshold {rec.threshold:g})")
        out.append({"image": str(path), "landmark": rec.name, "best": rec.best, "score_ransac": rec.score,
                    "score": score_nn, "b_s": None if math.isnan(b_s) else b_s,     # null: no consistent line
                    "b_d": None if math.isnan(b_d) else b_d, "threshold": rec.threshold, "scores": rec.scores})
    if args.json:
        from odometry.shared.atomic_io import atomic_write_text

        atomic_write_text(args.json, json.dumps(out, indent=2, default=float) + "\n")
    return 0


def _pairs(args: argparse.Namespace) -> int:
    rows = score_pairs_file(args.pairs, args.out, _params_from_args(args))
    print(f"wrote {args.out} ({len(rows)} pairs)")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    import numpy as np

    from loops.curves import auc, roc_curve, tpr_at_fpr

    path: Path = args.scores
    if not path.is_file():
        raise FileNotFoundError(f"{path}: scores file not found")
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        need = [args.label_column, *SCORE_COLUMNS[:2]]
        missing = [c for c in need if c not in header]
        if missing:
            raise VslamError(f"{path} line 1: missing column(s) {', '.join(missing)}")
        labels, cols = [], {c: [] for c in SCORE_COLUMNS[:2]}
        for line_no, row in enumerate(reader, start=2):
            try:
                lab = int(float(row[args.label_column]))
            except (TypeError, ValueError):
                raise VslamError(f"{path} line {line_no}, field {args.label_column}: "
                                 f"{row[args.label_column]!r} is not 0 or 1") from None
            if lab not in (0, 1):
                raise VslamError(f"{path} line {line_no}, field {args.label_column}: {lab} is not 0 or 1")
            labels.append(lab)
            for c in cols:
                try:
                    cols[c].append(float(row[c]))
                except (TypeError, ValueError):
                    raise VslamError(f"{path} line {line_no}, field {c}: {row[c]!r} is not a number") from None
    y = np.array(labels, bool)
    if y.all() or not y.any():
        raise VslamError(f"{path}: need both label 1 and label 0 rows for an ROC ({int(y.sum())} / {len(y)} are 1)")
    print(f"{len(y)} pairs: {int(y.sum())} matched, {int((~y).sum())} unmatched")
    curves = {}
    for c, name in (("score", "NN"), ("score_ransac", "NN+RANSAC")):
        s = np.array(cols[c])
        a = auc(s, y)
        tpr, thr = tpr_at_fpr(s, y, args.max_fpr)
        curves[f"1D SURF, {name}"] = (*roc_curve(s, y)[:2], a)
        print(f"{name:10s} AUC {a:.3f}; at <= {args.max_fpr:.0%} false positives: {tpr:.1%} matched, "
              f"threshold {thr:.4g}")
    if args.plot:
        write_roc_png(args.plot, curves, f"{path.name}: {int(y.sum())} matched / {int((~y).sum())} unmatched")
        print(f"wrote {args.plot}")
    return 0


def _add_params_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="paper", help="HorizonParams preset (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a HorizonParams field, e.g. --set threshold=20 (repeatable)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter  # keep the usage block of the description
    sub = parser.add_subparsers(dest="horizon_command", metavar="ACTION")
    sub.required = True

    p = sub.add_parser("memorise", help="extract and store landmarks (one per image) in a memory file")
    p.add_argument("images", nargs="+", type=Path, help="images to memorise")
    p.add_argument("--row", required=True, help="horizon row (or LEFT:RIGHT) in every image")
    p.add_argument("--out", type=Path, required=True, help="memory file to write (.npz)")
    p.add_argument("--names", nargs="+", help="landmark names (default: image file stems)")
    p.add_argument("--append", action="store_true", help="add to an existing memory instead of replacing it")
    _add_params_args(p)
    p.set_defaults(func=_memorise)

    p = sub.add_parser("recognise", help="which stored landmark (if any) each image shows")
    p.add_argument("memory", type=Path, help="memory file written by `vslam horizon memorise`")
    p.add_argument("images", nargs="+", type=Path, help="images to recognise")
    p.add_argument("--row", required=True, help="horizon row (or LEFT:RIGHT) in every image")
    p.add_argument("--threshold", type=float, default=None,
                   help="NN+RANSAC score needed to recognise (default: the memory's recognition_threshold)")
    p.add_argument("--json", type=Path, help="also write the results as JSON")
    p.set_defaults(func=_recognise)

    p = sub.add_parser("pairs", help="score image pairs: PAIRS.csv (a,b,row_a,row_b) -> SCORES.csv")
    p.add_argument("pairs", type=Path, help="CSV with columns a,b,row_a,row_b (other columns are copied)")
    p.add_argument("--out", type=Path, required=True,
                   help="CSV to write: the input columns + score,score_ransac,b_s,b_d")
    _add_params_args(p)
    p.set_defaults(func=_pairs)

    p = sub.add_parser("evaluate", help="ROC / AUC of a SCORES.csv that has a 0/1 label column")
    p.add_argument("scores", type=Path, help="CSV written by `vslam horizon pairs`")
    p.add_argument("--label-column", default="label", help="column with 1 = same landmark (default: %(default)s)")
    p.add_argument("--max-fpr", type=float, default=0.05, help="report the best sensitivity at this false "
                   "positive rate (default: %(default)s)")
    p.add_argument("--plot", type=Path, help="write the ROC curve as a PNG")
    p.set_defaults(func=_evaluate)


def run(args: argparse.Namespace) -> int:  # pragma: no cover - argparse dispatches to the action
    return args.func(args)

