"""`vslam bench horizon`: 1D SURF horizon landmarks against full-image SIFT on a matched / unmatched pair bank.

The bank mimics the classification experiment of Anderson et al. (§4.1), where a robot turned on the spot and two
views "match" when their headings differ by less than 20 degrees. Here the views are 640-pixel crops of the real,
wide KITTI frames in ../shared/data/places/kitti_snippets: a crop at horizontal offset o looks along the ray of its
centre column, so shifting the crop turns the view (a 640-px crop at fx = 707 spans 48.7 degrees, the robot's
camera 47.8). Frames further along the drive add translation (scale change) and, in the second snippet, the car's
own 98-degree turn. See `build_bank` for the exact recipe.

Everything is measured in one run: 1D SURF extraction and matching times (medians over many in-process calls),
OpenCV SIFT extraction and matching on the same crops, ROC curves and AUCs for the three scorers.
"""
from __future__ import annotations

import argparse
import csv
import shlex
import time
from pathlib import Path

import cv2
import numpy as np

from loops.curves import auc, roc_curve, tpr_at_fpr
from loops.horizon import HorizonParams, extract_features, match, nn_matches
from loops.horizon.pairs_file import SCORE_COLUMNS, score_pairs_file
from odometry.shared.atomic_io import atomic_path, atomic_write_text
from vslam.app.horizon import horizon_params
from vslam.bench.docs import publish
from vslam.bench.horizon_bank import SNIPPETS, Bank, build_bank, load_crops
from vslam.bench.horizon_fast import PairSet, compare
from vslam.bench.horizon_real import build_real_bank, real_pairs_table
from vslam.bench.results import BenchResult, write_json
from vslam.evaluation.plots import plot_roc_curves
from vslam.evaluation.tables import format_table
from vslam.paths import shared_data_dir

# KITTI pairs from ../shared/data/pairs where a horizon row makes sense (the level car camera, row = cy).
# The other pairs there are hand-held / tilted views (TUM office) or planar and object scenes (graf, churchill,
# box, mars, ship, bicycle, SOH, kn_church) that have no horizon to read.
KITTI_PAIR_ROW = 183  # cy = 183.1 for KITTI 06 (calibration in kitti_snippets)
SIFT = "SIFT (full image), NN"
NN, NN_RANSAC = "1D SURF, NN", "1D SURF, NN+RANSAC"


def _median_us(xs: list[float]) -> float:
    return float(np.median(xs) * 1e6) if len(xs) else float("nan")


def time_horizon(crops, rows, pairs, params, repeat: int) -> tuple[list[float], list[float], list[float]]:
    """Per-call seconds of 1D SURF extraction (every view), matching and NN-only matching (every pair), over
    `repeat` rounds; in-process, one call at a time, so the medians are per-call times."""
    feats = [extract_features(c, r, params) for c, r in zip(crops, rows)]
    for f in feats:
        f.keys  # matching keys are built once per feature set (at memorise time for stored landmarks)
    t_ext, t_match, t_nn = [], [], []
    clock = time.perf_counter
    for _ in range(repeat):
        for c, r in zip(crops, rows):
            t0 = clock()
            extract_features(c, r, params)
            t_ext.append(clock() - t0)
        for a, b in pairs:
            fa, fb = feats[a], feats[b]
            t0 = clock()
            match(fb, fa, params)
            t_match.append(clock() - t0)
        for a, b in pairs:
            fa, fb = feats[a], feats[b]
            t0 = clock()
            nn_matches(fb, fa, params)
            t_nn.append(clock() - t0)
    return t_ext, t_match, t_nn


class SiftReference:
    """Full-image SIFT (OpenCV), NN ratio test, score = sum of 1 / descriptor distance: the paper's SURF
    reference (OpenCV's plain wheel has no SURF). Features are computed once per view, timed."""

    def __init__(self, crops, n_features: int, ratio: float):
        self.crops, self.ratio = crops, ratio
        self.sift = cv2.SIFT_create(nfeatures=n_features)
        self.bf = cv2.BFMatcher(cv2.NORM_L2)
        self.desc: dict[int, np.ndarray] = {}
        self.t_ext: list[float] = []
        self.t_match: list[float] = []
        self.scores: dict[tuple[int, int], float] = {}

    def features(self, v: int) -> np.ndarray:
        if v not in self.desc:
            t0 = time.perf_counter()
            _, d = self.sift.detectAndCompute(self.crops[v], None)
            self.t_ext.append(time.perf_counter() - t0)
            self.desc[v] = d if d is not None else np.zeros((0, 128), np.float32)
        return self.desc[v]

    def score(self, a: int, b: int) -> float:
        if (a, b) not in self.scores:
            da, db = self.features(a), self.features(b)
            t0 = time.perf_counter()
            s = 0.0
            if len(da) >= 2 and len(db) >= 1:
                for m in self.bf.knnMatch(db, da, k=2):
                    if len(m) == 2 and m[0].distance < self.ratio * m[1].distance:
                        s += 1.0 / max(m[0].distance, 1e-6)
            self.t_match.append(time.perf_counter() - t0)
            self.scores[(a, b)] = s
        return self.scores[(a, b)]

    @property
    def mean_features(self) -> float:
        return float(np.mean([len(d) for d in self.desc.values()])) if self.desc else float("nan")


def _kitti_pairs_csv(data_dir: Path, out_csv: Path) -> Path:
    """The KITTI pairs of ../shared/data/pairs as a PAIRS.csv (a, b, row_a, row_b, label) for `vslam horizon pairs`."""
    pairs_dir = data_dir / "pairs"
    lines = ["a,b,row_a,row_b,label"]
    for ln in (pairs_dir / "pairs.txt").read_text().splitlines():
        parts = ln.split()
        if len(parts) == 3 and parts[0].startswith("kitti") and parts[1].startswith("kitti"):
            a, b = (str(pairs_dir / "images" / f"{p}.png") for p in parts[:2])
            lines.append(f"{a},{b},{KITTI_PAIR_ROW},{KITTI_PAIR_ROW},{parts[2]}")
    atomic_write_text(out_csv, "\n".join(lines) + "\n")
    return out_csv


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("out/bench_horizon"),
                        help="output folder: horizon.json, roc.png, bank_scores.csv, kitti_pairs*.csv "
                             "(default: %(default)s)")
    parser.add_argument("--preset", default="paper", help="HorizonParams preset (default: %(default)s)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a HorizonParams field, e.g. --set threshold=2 (repeatable)")
    parser.add_argument("--max-baseline", type=float, default=2.5,
                        help="metres between camera centres allowed in a matched pair of the main bank "
                             "(default: %(default)s)")
    parser.add_argument("--sweep", type=str, default="0,2.5,4,6.5",
                        help="comma-separated max baselines for the AUC sweep table (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="bank sampling seed (default: %(default)s)")
    parser.add_argument("--repeat", type=int, default=20,
                        help="timing rounds over all views / pairs for 1D SURF (default: %(default)s)")
    parser.add_argument("--sift-features", type=int, default=1000,
                        help="SIFT keypoints per crop, 0 = no limit (default: %(default)s)")
    parser.add_argument("--no-sift", action="store_true", help="skip the SIFT reference (quick tuning runs)")
    parser.add_argument("--quick", action="store_true", help="a smaller bank (120 matched / 500 unmatched pairs)")
    parser.add_argument("--real-only", action="store_true",
                        help="only the real pairs (corridor + KITTI pairs: 1D SURF vs ORB + RANSAC), not the crop bank")
    parser.add_argument("--bands-preset", default="bands",
                        help="HorizonParams preset of the multi-band 1D SURF on the real pairs (default: %(default)s)")
    parser.add_argument("--fast-preset", default="fast",
                        help="HorizonParams preset of the packed 1D SURF compared with ORB + RANSAC per image and "
                             "per pair (default: %(default)s)")
    parser.add_argument("--lone-preset", default="lone,lone_compiled",
                        help="more packed presets in the same comparison (comma-separated), those for a lone pair; "
                             "'' for none (default: %(default)s)")
    parser.add_argument("--threads", type=int, default=1,
                        help="OpenCV threads for SIFT; 1 compares single core with single core (default: 1)")


def _auc_or_nan(scores, labels) -> float:
    y = np.asarray(labels, bool)
    return auc(scores, y) if y.any() and not y.all() else float("nan")


# ---------------------------------------------------------------------------------------------------- stages
def _banks(args: argparse.Namespace, data_dir: Path) -> dict[float, Bank]:
    """A bank per max baseline of the sweep (and of --max-baseline); they share views and unmatched pairs."""
    n_m, n_u = (120, 500) if args.quick else (480, 2065)
    try:
        sweep = sorted({float(b) for b in args.sweep.split(",") if b.strip()} | {args.max_baseline})
    except ValueError:
        raise ValueError(f"--sweep: expected comma-separated numbers, got {args.sweep!r}") from None
    return {b: build_bank(data_dir, max_baseline=b, n_matched=n_m, n_unmatched=n_u, seed=args.seed) for b in sweep}


def _other_presets(params: HorizonParams, crops, rows, bank: Bank) -> dict[str, float]:
    """NN+RANSAC AUC of the paper / robust presets that differ from the parameters used."""
    compare = {name: p for name, p in (("paper", HorizonParams.preset("paper")),
                                       ("robust", HorizonParams.preset("robust"))) if p != params}
    out = {}
    for name, p in compare.items():
        fs = [extract_features(c, r, p) for c, r in zip(crops, rows)]
        out[name] = _auc_or_nan([match(fs[b], fs[a], p).score_ransac for a, b in bank.pairs], bank.labels)
    return out


def _scores(bank: Bank, res: dict, sift: SiftReference | None) -> dict[str, np.ndarray]:
    """Each scorer's score of every pair of a bank."""
    out = {}
    if sift is not None:
        out[SIFT] = np.array([sift.score(int(a), int(b)) for a, b in bank.pairs])
    out[NN] = np.array([res[(int(a), int(b))].score for a, b in bank.pairs])
    out[NN_RANSAC] = np.array([res[(int(a), int(b))].score_ransac for a, b in bank.pairs])
    return out


def _speed(t_ext, t_match, t_nn, feats, sift: SiftReference | None) -> tuple[dict, dict, dict]:
    """Median extraction and matching microseconds and mean features per view, per scorer."""
    ext = {NN: _median_us(t_ext), NN_RANSAC: _median_us(t_ext)}
    mat = {NN: _median_us(t_nn), NN_RANSAC: _median_us(t_match)}
    nfeat = {NN: float(np.mean([len(f) for f in feats]))}
    nfeat[NN_RANSAC] = nfeat[NN]
    if sift is not None:
        ext[SIFT] = _median_us(sift.t_ext)
        mat[SIFT] = _median_us(sift.t_match)
        nfeat[SIFT] = sift.mean_features
    return ext, mat, nfeat


def _main_table(bank: Bank, scorers: dict, aucs: dict, ext, mat, nfeat) -> tuple[str, dict]:
    """The speed / AUC table of the main bank, and the AUCs on rotation-only and rotation+translation matches."""
    y = bank.labels
    subsets = {}
    for kind in ("rotation", "rotation+translation"):
        keep = (bank.kind == kind) | ~y
        subsets[kind] = {k: _auc_or_nan(s[keep], y[keep]) for k, s in scorers.items()}
    sift_ext, sift_mat = ext.get(SIFT, float("nan")), mat.get(SIFT, float("nan"))
    rows = [[k, nfeat[k], ext[k] / 1e3, mat[k] / 1e3, sift_ext / ext[k], sift_mat / mat[k], aucs[k],
             subsets["rotation"][k], subsets["rotation+translation"][k]] for k in scorers]
    table = format_table(["method", "features / view", "extraction ms", "matching ms", "SIFT / this, extraction",
                          "SIFT / this, matching", "AUC", "AUC, rotation-only matches",
                          "AUC, rotation+translation matches"], rows, floatfmt=".4g")
    return table, subsets


def _sweep(banks: dict[float, Bank], res: dict, sift, scorer_names) -> tuple[str, dict]:
    """AUC per scorer for each max baseline."""
    rows, out = [], {}
    for b, bk in banks.items():
        sc = _scores(bk, res, sift)
        a = {k: _auc_or_nan(s, bk.labels) for k, s in sc.items()}
        n_rot = int((bk.kind == "rotation").sum())
        n_tr = int((bk.kind == "rotation+translation").sum())
        rows.append([f"{b:g}", f"{n_rot} / {n_tr}", *[a[k] for k in sc]])
        out[f"{b:g}"] = {"matched_rotation": n_rot, "matched_rotation_translation": n_tr, "auc": a}
    return format_table(["max baseline m", "matched: rotation / rot.+transl.", *scorer_names], rows,
                        floatfmt=".3f"), out


def _by_drive(bank: Bank, scorers: dict) -> dict[str, dict]:
    """AUC per scorer over the pairs within each drive."""
    snip_a = np.array([bank.views[a].snippet for a, _ in bank.pairs])
    snip_b = np.array([bank.views[b].snippet for _, b in bank.pairs])
    out = {}
    for si, name in enumerate(SNIPPETS):
        keep = (snip_a == si) & (snip_b == si)
        out[name] = {k: _auc_or_nan(s[keep], bank.labels[keep]) for k, s in scorers.items()}
    return out


def _write_bank_scores(path: Path, bank: Bank, res: dict, scorers: dict) -> None:
    """Every pair of the main bank with its label, kind, geometry and scores, as CSV."""
    y, has_sift = bank.labels, SIFT in scorers
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["a", "b", "row_a", "row_b", "label", "kind", "heading_diff_deg", "baseline_m", *SCORE_COLUMNS,
                    *(["score_sift"] if has_sift else [])])
        for p, (a, b) in enumerate(bank.pairs):
            va, vb, r = bank.views[a], bank.views[b], res[(int(a), int(b))]
            dh = abs((va.heading_deg - vb.heading_deg + 180) % 360 - 180)
            base = float(np.linalg.norm(np.subtract(va.position, vb.position)))
            line = [f"{SNIPPETS[va.snippet]}/{va.path.name}@{va.offset}",
                    f"{SNIPPETS[vb.snippet]}/{vb.path.name}@{vb.offset}", va.row, vb.row, int(y[p]), bank.kind[p],
                    f"{dh:.2f}", f"{base:.2f}", f"{r.score:.4f}", f"{r.score_ransac:.4f}", f"{r.b_s:.5f}",
                    f"{r.b_d:.3f}"]
            if has_sift:
                line.append(f"{scorers[SIFT][p]:.5f}")
            w.writerow(line)


def _kitti_pairs(data_dir: Path, out: Path, params: HorizonParams) -> tuple[list[dict], dict, str]:
    """The real KITTI pairs of ../shared/data/pairs, through the same code path as `vslam horizon pairs`."""
    pairs_csv = _kitti_pairs_csv(data_dir, out / "kitti_pairs.csv")
    scored = score_pairs_file(pairs_csv, out / "kitti_pairs_scores.csv", params)
    lab = np.array([int(r["label"]) for r in scored])
    pair_auc = {NN: _auc_or_nan([r["score"] for r in scored], lab),
                NN_RANSAC: _auc_or_nan([r["score_ransac"] for r in scored], lab)}
    line = (f"KITTI pairs of ../shared/data/pairs ({int(lab.sum())} same place / {int((lab == 0).sum())} "
            f"different place, full 1226-px frames, row {KITTI_PAIR_ROW}): AUC NN {pair_auc[NN]:.3f}, "
            f"NN+RANSAC {pair_auc[NN_RANSAC]:.3f}")
    return scored, pair_auc, line


# ---------------------------------------------------------------------------------------------------- the run
def _measure(args: argparse.Namespace, params: HorizonParams, banks: dict[float, Bank]) -> dict:
    """Scores of every pair of every bank, the other presets' AUC, the timings and the SIFT reference."""
    bank = banks[args.max_baseline]
    crops = load_crops(bank)
    rows = [v.row for v in bank.views]
    y = bank.labels
    print(f"bank: {len(bank.views)} views (640-px crops of {len(bank.views) // 12} KITTI frames), "
          f"{int(y.sum())} matched / {int((~y).sum())} unmatched pairs, max baseline {args.max_baseline:g} m",
          flush=True)
    feats = [extract_features(c, r, params) for c, r in zip(crops, rows)]
    union = sorted({(int(a), int(b)) for bk in banks.values() for a, b in bk.pairs})
    res = {(a, b): match(feats[b], feats[a], params) for a, b in union}
    compare_auc = _other_presets(params, crops, rows, bank)
    print(f"timing 1D SURF ({args.repeat} rounds) ...", flush=True)
    timing = time_horizon(crops, rows, bank.pairs, params, args.repeat)
    sift = None
    if not args.no_sift:
        print(f"SIFT reference on {len(union)} pairs ...", flush=True)
        sift = SiftReference(crops, args.sift_features, params.ratio)
        for a, b in union:
            sift.score(a, b)
    return {"bank": bank, "feats": feats, "res": res, "compare_auc": compare_auc, "timing": timing, "sift": sift}


def _real(args: argparse.Namespace, data_dir: Path) -> tuple[str, dict]:
    print("real pairs (corridor + KITTI pairs): 1D SURF vs ORB + RANSAC ...", flush=True)
    text, res = real_pairs_table(data_dir, HorizonParams.preset(args.bands_preset))
    print(text, flush=True)
    print("real pairs: packed 1D SURF vs ORB + RANSAC, per image and per pair ...", flush=True)
    bank = build_real_bank(data_dir)
    fast_table, fast_res = compare(PairSet(bank.images, bank.rows, bank.pairs, bank.labels, bank.half),
                                   _packed_presets(args), {"tuning": 0, "reporting": 1})
    head = (f"Packed 1D SURF (presets {', '.join(_packed_presets(args))}) against ORB + RANSAC on the same real "
            f"pairs, thread CPU time, the methods taking turns every 16 images / test views (definitions in "
            f"vslam/bench/horizon_fast.py and docs/benchmarks.md).")
    print(f"{head}\n\n{fast_table}", flush=True)
    res["packed_vs_orb"] = fast_res
    return f"{text}\n\n{head}\n\n{fast_table}", res


def _packed_presets(args: argparse.Namespace) -> dict[str, HorizonParams]:
    names = [args.fast_preset] + [n.strip() for n in args.lone_preset.split(",") if n.strip()]
    return {n: HorizonParams.preset(n) for n in dict.fromkeys(names)}


def _crop_bank_fast(args: argparse.Namespace, bank: Bank) -> tuple[str, dict]:
    """The packed 1D SURF against ORB + RANSAC on our own crop bank (nothing was tuned on it)."""
    print("crop bank: packed 1D SURF vs ORB + RANSAC, per image and per pair ...", flush=True)
    crops = load_crops(bank)
    names = [str(i) for i in range(len(bank.views))]
    ps = PairSet(dict(zip(names, crops)), {n: float(v.row) for n, v in zip(names, bank.views)},
                 [(names[a], names[b]) for a, b in bank.pairs], bank.labels, np.zeros(len(bank.pairs), int))
    table, res = compare(ps, _packed_presets(args), {"crop bank (all; nothing tuned here)": None})
    text = (f"Packed 1D SURF (presets {', '.join(_packed_presets(args))}) against ORB + RANSAC on the crop bank "
            f"above.\n\n{table}")
    print(text, flush=True)
    return text, res


def run(args: argparse.Namespace) -> BenchResult:
    data_dir = shared_data_dir(required=True)
    params = horizon_params(args.preset, args.overrides)
    if args.real_only:
        text, res = _real(args, data_dir)
        write_json(args.out / "horizon_real.json", {"benchmark": "horizon-real", "real_pairs": res, "table": text})
        publish_sections(args, {"horizon-real": text})
        return BenchResult(None)
    cv2.setNumThreads(max(1, args.threads))
    banks = _banks(args, data_dir)
    m = _measure(args, params, banks)
    bank, res, sift, (t_ext, t_match, t_nn) = m["bank"], m["res"], m["sift"], m["timing"]
    y = bank.labels
    scorers = _scores(bank, res, sift)
    aucs = {k: _auc_or_nan(s, y) for k, s in scorers.items()}
    ext, mat, nfeat = _speed(t_ext, t_match, t_nn, m["feats"], sift)
    table, subsets = _main_table(bank, scorers, aucs, ext, mat, nfeat)
    sweep_table, sweep_json = _sweep(banks, res, sift, list(scorers))
    by_drive = _by_drive(bank, scorers)
    tpr5, thr5 = tpr_at_fpr(scorers[NN_RANSAC], y, 0.05)
    lines = ([f"{name} (pairs within the drive): " + ", ".join(f"{k} AUC {v:.3f}" for k, v in d.items())
              for name, d in by_drive.items()]
             + [f"preset {name!r}: NN+RANSAC AUC {a:.3f}" for name, a in m["compare_auc"].items()]
             + [f"NN+RANSAC at <= 5% false positives: {tpr5:.1%} of matched pairs, score threshold {thr5:.1f}"])
    print(f"{table}\n\n{sweep_table}\n" + "\n".join(lines))

    args.out.mkdir(parents=True, exist_ok=True)
    plot_roc_curves(args.out / "roc.png", {k: (*roc_curve(s, y)[:2], aucs[k]) for k, s in scorers.items()},
                    f"KITTI crop bank: {int(y.sum())} matched / {int((~y).sum())} unmatched pairs")
    _write_bank_scores(args.out / "bank_scores.csv", bank, res, scorers)
    scored, pair_auc, kitti_line = _kitti_pairs(data_dir, args.out, params)
    print(kitti_line)
    real_text, real_res = _real(args, data_dir)
    crop_fast_text, crop_fast_res = _crop_bank_fast(args, bank)
    cv2.setNumThreads(max(1, args.threads))

    write_json(args.out / "horizon.json", {
        "benchmark": "horizon",
        "command": "vslam bench horizon " + " ".join(_argv_echo(args)),
        "params": params.to_dict(),
        "bank": {"views": len(bank.views), "matched": int(y.sum()), "unmatched": int((~y).sum()),
                 "kinds": {k: int((bank.kind == k).sum()) for k in np.unique(bank.kind)}, "seed": args.seed,
                 "snippets": list(SNIPPETS), "crop": bank.crop, "max_baseline_m": args.max_baseline,
                 "horizon_rows": sorted({v.row for v in bank.views})},
        "auc": aucs, "auc_by_subset": subsets, "auc_by_drive": by_drive, "auc_sweep": sweep_json,
        "auc_other_presets": m["compare_auc"],
        "extraction_us_median": ext, "matching_us_median": mat, "mean_features": nfeat,
        "timing_calls": {"extraction": len(t_ext), "matching": len(t_match), "nn_only": len(t_nn),
                         "sift_extraction": len(sift.t_ext) if sift else 0,
                         "sift_matching": len(sift.t_match) if sift else 0},
        "sift_features_cap": args.sift_features, "opencv_threads": args.threads,
        "nn_ransac_at_5pct_fpr": {"tpr": tpr5, "threshold": thr5},
        "kitti_pairs": {"auc": pair_auc, "pairs": scored}, "real_pairs": real_res,
        "crop_bank_packed_vs_orb": crop_fast_res,
        "table": table, "sweep_table": sweep_table,
    })
    print(f"wrote {args.out / 'horizon.json'}, {args.out / 'roc.png'}, {args.out / 'bank_scores.csv'}")
    publish_sections(args, {"horizon-real": real_text, "horizon-packed-crop": crop_fast_text})
    if args.no_sift:    # the crop bank's tables without their SIFT reference do not replace the documented ones
        return BenchResult(None)
    return BenchResult(f"{table}\n\n{sweep_table}\n\n" + "\n\n".join(lines + [kitti_line]))


def publish_sections(args: argparse.Namespace, sections: dict[str, str]) -> None:
    """The real-pairs and packed tables into their own sections of docs/benchmarks.md (horizon-real,
    horizon-packed-crop), under the CLI's --docs / --no-docs / --docs-file; the crop bank's own tables go to the
    `horizon` section through the registry as before."""
    command = "vslam " + shlex.join(getattr(args, "command_line", None) or ["bench", "horizon"])
    for name, text in sections.items():
        note = publish(name, text, command, getattr(args, "docs", None), getattr(args, "docs_file", None))
        if note:
            print(note)


def _argv_echo(args: argparse.Namespace) -> list[str]:
    out = [f"--out {args.out}", f"--preset {args.preset}", f"--max-baseline {args.max_baseline:g}",
           f"--sweep {args.sweep}", f"--seed {args.seed}", f"--repeat {args.repeat}",
           f"--sift-features {args.sift_features}", f"--threads {args.threads}"]
    out += [f"--set {o}" for o in args.overrides]
    out += ["--no-sift"] if args.no_sift else []
    out += ["--quick"] if args.quick else []
    out += ["--real-only"] if args.real_only else []
    out += [f"--fast-preset {args.fast_preset}", f"--lone-preset {args.lone_preset or repr('')}"]
    return out
