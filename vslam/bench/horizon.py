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
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

NAME = "horizon"
HELP = "1D SURF horizon landmarks vs SIFT: ROC/AUC on a KITTI crop bank, extraction and matching time"

SNIPPETS = ("KITTI_sequence_1_kitti06_f0000-0050", "KITTI_sequence_2_unidentified_seq00-02calib")
# KITTI pairs from ../shared/data/pairs where a horizon row makes sense (the level car camera, row = cy).
# The other pairs there are hand-held / tilted views (TUM office) or planar and object scenes (graf, churchill,
# box, mars, ship, bicycle, SOH, kn_church) that have no horizon to read.
KITTI_PAIR_ROW = 183  # cy = 183.1 for KITTI 06 (calibration in kitti_snippets)


@dataclass(frozen=True)
class View:
    snippet: int        # index into SNIPPETS
    frame: int
    offset: int         # crop's first column in the full frame
    path: Path
    row: int            # horizon row (the principal point row cy, rounded: the KITTI camera is level)
    heading_deg: float  # world heading of the crop centre's ray
    position: tuple[float, float, float]


@dataclass(frozen=True)
class Bank:
    views: list[View]
    pairs: np.ndarray       # (P, 2) view indices
    labels: np.ndarray      # (P,) bool: matched
    kind: np.ndarray        # (P,) str: rotation | rotation+translation | unmatched-same-drive | unmatched-other-drive
    crop: int


def read_kitti_snippet(folder: Path) -> tuple[dict, np.ndarray, list[Path]]:
    """(calibration {fx, cx, cy}, (N, 3, 4) camera poses, image paths) of a kitti_snippets folder, via the
    toolkit's KITTI reader."""
    from odometry.shared.tum import tum_to_se3_matrices
    from vslam.io import read_kitti

    seq = read_kitti(folder)
    if seq.groundtruth is None:
        raise ValueError(f"{folder}: no poses.txt (the bank needs ground-truth headings)")
    poses = tum_to_se3_matrices(seq.groundtruth.poses)[:, :3, :]
    cam = seq.camera
    return {"fx": cam.fx, "cx": cam.cx, "cy": cam.cy}, poses, [seq.images.path(i) for i in range(len(seq))]


def _ray_heading(rotation: np.ndarray, u: float, fx: float, cx: float) -> float:
    # KITTI camera: x right, y down, z forward. Heading of the ray through column u, on the ground plane (x-z).
    d = rotation @ np.array([(u - cx) / fx, 0.0, 1.0])
    return float(np.degrees(np.arctan2(d[0], d[2])))


def build_bank(data_dir: Path, frame_step: int = 2, n_offsets: int = 12, crop: int = 640, match_deg: float = 20.0,
               max_baseline: float = 2.5, n_matched: int = 480, n_unmatched: int = 2065, seed: int = 0) -> Bank:
    """The classification bank (deterministic for a seed).

    Views: frames 0, frame_step, ... of each snippet; in each, n_offsets crops of `crop` px at offsets
    round(linspace(0, W - crop, n_offsets)) (about 4.3 degrees apart, like the paper's 4-degree turns).
    Labels: matched when the crop-centre rays differ by < match_deg in heading and the camera centres are at most
    max_baseline metres apart (same frame: pure rotation, the paper's protocol; nearby frames: rotation plus
    translation, i.e. scale change); unmatched when the headings differ by >= match_deg (same drive, any distance)
    or the views come from different drives. Same-drive pairs within match_deg but further apart than max_baseline
    are left out: a heading label only says "same landmark" when the landmarks are far compared to the baseline.
    Then n_matched / n_unmatched pairs are drawn without replacement (the paper's 480 and 2,065), the unmatched
    ones 3:1 from the same drive. Each draw has its own random stream, so banks that differ only in
    max_baseline share their unmatched pairs.
    """
    root = data_dir / "places" / "kitti_snippets"
    views: list[View] = []
    for si, name in enumerate(SNIPPETS):
        calib, poses, images = read_kitti_snippet(root / name)
        import cv2

        first = cv2.imread(str(images[0]), cv2.IMREAD_GRAYSCALE)
        if first is None:
            raise OSError(f"{images[0]}: cannot read image")
        offsets = np.rint(np.linspace(0, first.shape[1] - crop, n_offsets)).astype(int)
        row = int(round(calib["cy"]))
        for f in range(0, len(images), frame_step):
            r, t = poses[f, :, :3], poses[f, :, 3]
            for o in offsets:
                heading = _ray_heading(r, o + (crop - 1) / 2.0, calib["fx"], calib["cx"])
                views.append(View(si, f, int(o), images[f], row, heading, tuple(float(v) for v in t)))

    snip = np.array([v.snippet for v in views])
    head = np.array([v.heading_deg for v in views])
    pos = np.array([v.position for v in views])
    frame = np.array([v.frame for v in views])
    i, j = np.triu_indices(len(views), 1)
    same = snip[i] == snip[j]
    dh = np.abs((head[i] - head[j] + 180.0) % 360.0 - 180.0)
    base = np.linalg.norm(pos[i] - pos[j], axis=1)
    matched = same & (dh < match_deg) & (base <= max_baseline)
    unmatched_same = same & (dh >= match_deg)
    other = ~same

    def draw(mask: np.ndarray, k: int, stream: int) -> np.ndarray:
        idx = np.flatnonzero(mask)
        rng = np.random.default_rng([seed, stream])
        return np.sort(rng.choice(idx, size=min(k, idx.size), replace=False))

    pick_m = draw(matched, n_matched, 1)
    n_same = min(int(round(0.75 * n_unmatched)), int(unmatched_same.sum()))
    pick_u = draw(unmatched_same, n_same, 2)
    pick_o = draw(other, n_unmatched - n_same, 3)
    sel = np.r_[pick_m, pick_u, pick_o]
    kind = np.r_[np.where(frame[i[pick_m]] == frame[j[pick_m]], "rotation", "rotation+translation"),
                 np.full(pick_u.size, "unmatched-same-drive"), np.full(pick_o.size, "unmatched-other-drive")]
    labels = np.r_[np.ones(pick_m.size, bool), np.zeros(pick_u.size + pick_o.size, bool)]
    return Bank(views, np.stack([i[sel], j[sel]], axis=1), labels, kind, crop)


def _load_crops(bank: Bank) -> list[np.ndarray]:
    import cv2

    cache: dict[Path, np.ndarray] = {}
    crops = []
    for v in bank.views:
        if v.path not in cache:
            img = cv2.imread(str(v.path), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise OSError(f"{v.path}: cannot read image")
            cache[v.path] = img
        crops.append(np.ascontiguousarray(cache[v.path][:, v.offset:v.offset + bank.crop]))
    return crops


def _median_us(xs: list[float]) -> float:
    return float(np.median(xs) * 1e6) if len(xs) else float("nan")


def time_horizon(crops, rows, pairs, params, repeat: int) -> tuple[list[float], list[float], list[float]]:
    """Per-call seconds of 1D SURF extraction (every view), matching and NN-only matching (every pair), over
    `repeat` rounds; in-process, one call at a time, so the medians are per-call times."""
    from loops.horizon import extract_features, match, nn_matches

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
        import cv2

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
    from odometry.shared.atomic_io import atomic_write_text

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
    parser.add_argument("--threads", type=int, default=1,
                        help="OpenCV threads for SIFT; 1 compares single core with single core (default: 1)")


def _auc_or_nan(scores, labels) -> float:
    from loops.curves import auc

    y = np.asarray(labels, bool)
    return auc(scores, y) if y.any() and not y.all() else float("nan")


def run(args: argparse.Namespace) -> int:
    import cv2

    from loops.curves import roc_curve, tpr_at_fpr
    from loops.horizon import HorizonParams, extract_features, match
    from odometry.shared.atomic_io import atomic_path
    from vslam.bench._common import format_table, write_json
    from vslam.cli.cmd_horizon import parse_overrides, score_pairs_file, write_roc_png
    from vslam.paths import shared_data_dir

    data_dir = shared_data_dir(required=True)
    params = parse_overrides(HorizonParams.preset(args.preset), args.overrides)
    cv2.setNumThreads(max(1, args.threads))
    n_m, n_u = (120, 500) if args.quick else (480, 2065)
    try:
        sweep = sorted({float(b) for b in args.sweep.split(",") if b.strip()} | {args.max_baseline})
    except ValueError:
        raise ValueError(f"--sweep: expected comma-separated numbers, got {args.sweep!r}") from None
    banks = {b: build_bank(data_dir, max_baseline=b, n_matched=n_m, n_unmatched=n_u, seed=args.seed) for b in sweep}
    bank = banks[args.max_baseline]
    crops = _load_crops(bank)
    rows = [v.row for v in bank.views]
    y = bank.labels
    print(f"bank: {len(bank.views)} views (640-px crops of {len(bank.views) // 12} KITTI frames), "
          f"{int(y.sum())} matched / {int((~y).sum())} unmatched pairs, max baseline {args.max_baseline:g} m",
          flush=True)

    # Scores: every pair of every bank (the banks share views and unmatched pairs).
    feats = [extract_features(c, r, params) for c, r in zip(crops, rows)]
    union = sorted({(int(a), int(b)) for bk in banks.values() for a, b in bk.pairs})
    res = {(a, b): match(feats[b], feats[a], params) for a, b in union}
    compare = {name: p for name, p in (("paper", HorizonParams.preset("paper")),
                                       ("robust", HorizonParams.preset("robust"))) if p != params}
    compare_auc = {}
    for name, p in compare.items():
        fs = [extract_features(c, r, p) for c, r in zip(crops, rows)]
        compare_auc[name] = _auc_or_nan([match(fs[b], fs[a], p).score_ransac for a, b in bank.pairs], y)

    print(f"timing 1D SURF ({args.repeat} rounds) ...", flush=True)
    t_ext, t_match, t_nn = time_horizon(crops, rows, bank.pairs, params, args.repeat)

    def scores_for(bk: Bank) -> dict[str, np.ndarray]:
        out = {}
        if sift is not None:
            out["SIFT (full image), NN"] = np.array([sift.score(int(a), int(b)) for a, b in bk.pairs])
        out["1D SURF, NN"] = np.array([res[(int(a), int(b))].score for a, b in bk.pairs])
        out["1D SURF, NN+RANSAC"] = np.array([res[(int(a), int(b))].score_ransac for a, b in bk.pairs])
        return out

    sift = None
    if not args.no_sift:
        print(f"SIFT reference on {len(union)} pairs ...", flush=True)
        sift = SiftReference(crops, args.sift_features, params.ratio)
        for a, b in union:
            sift.score(a, b)
    scorers = scores_for(bank)
    aucs = {k: _auc_or_nan(s, y) for k, s in scorers.items()}

    ext = {"1D SURF, NN": _median_us(t_ext), "1D SURF, NN+RANSAC": _median_us(t_ext)}
    mat = {"1D SURF, NN": _median_us(t_nn), "1D SURF, NN+RANSAC": _median_us(t_match)}
    nfeat = {"1D SURF, NN": float(np.mean([len(f) for f in feats]))}
    nfeat["1D SURF, NN+RANSAC"] = nfeat["1D SURF, NN"]
    if sift is not None:
        ext["SIFT (full image), NN"] = _median_us(sift.t_ext)
        mat["SIFT (full image), NN"] = _median_us(sift.t_match)
        nfeat["SIFT (full image), NN"] = sift.mean_features
    sift_ext = ext.get("SIFT (full image), NN", float("nan"))
    sift_mat = mat.get("SIFT (full image), NN", float("nan"))
    subsets = {}
    for kind in ("rotation", "rotation+translation"):
        keep = (bank.kind == kind) | ~y
        subsets[kind] = {k: _auc_or_nan(s[keep], y[keep]) for k, s in scorers.items()}
    table_rows = [[k, nfeat[k], ext[k] / 1e3, mat[k] / 1e3, sift_ext / ext[k], sift_mat / mat[k], aucs[k],
                   subsets["rotation"][k], subsets["rotation+translation"][k]] for k in scorers]
    table = format_table(["method", "features / view", "extraction ms", "matching ms", "SIFT / this, extraction",
                          "SIFT / this, matching", "AUC", "AUC, rotation-only matches",
                          "AUC, rotation+translation matches"], table_rows, floatfmt=".4g")

    sweep_rows, sweep_json = [], {}
    for b, bk in banks.items():
        sc = scores_for(bk)
        a = {k: _auc_or_nan(s, bk.labels) for k, s in sc.items()}
        n_rot = int((bk.kind == "rotation").sum())
        n_tr = int((bk.kind == "rotation+translation").sum())
        sweep_rows.append([f"{b:g}", f"{n_rot} / {n_tr}", *[a[k] for k in sc]])
        sweep_json[f"{b:g}"] = {"matched_rotation": n_rot, "matched_rotation_translation": n_tr, "auc": a}
    sweep_table = format_table(["max baseline m", "matched: rotation / rot.+transl.", *scorers], sweep_rows,
                               floatfmt=".3f")

    snip_a = np.array([bank.views[a].snippet for a, _ in bank.pairs])
    snip_b = np.array([bank.views[b].snippet for _, b in bank.pairs])
    by_drive = {}
    for si, name in enumerate(SNIPPETS):
        keep = (snip_a == si) & (snip_b == si)
        by_drive[name] = {k: _auc_or_nan(s[keep], y[keep]) for k, s in scorers.items()}

    print(table)
    print()
    print(sweep_table)
    for name, d in by_drive.items():
        print(f"{name} (pairs within the drive): " + ", ".join(f"{k} AUC {v:.3f}" for k, v in d.items()))
    for name, a in compare_auc.items():
        print(f"preset {name!r}: NN+RANSAC AUC {a:.3f}")
    tpr5, thr5 = tpr_at_fpr(scorers["1D SURF, NN+RANSAC"], y, 0.05)
    print(f"NN+RANSAC at <= 5% false positives: {tpr5:.1%} of matched pairs, score threshold {thr5:.1f}")

    args.out.mkdir(parents=True, exist_ok=True)
    write_roc_png(args.out / "roc.png", {k: (*roc_curve(s, y)[:2], aucs[k]) for k, s in scorers.items()},
             f"KITTI crop bank: {int(y.sum())} matched / {int((~y).sum())} unmatched pairs")
    with atomic_path(args.out / "bank_scores.csv") as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["a", "b", "row_a", "row_b", "label", "kind", "heading_diff_deg", "baseline_m", *SCORE_NAMES,
                    *(["score_sift"] if sift is not None else [])])
        for p, (a, b) in enumerate(bank.pairs):
            va, vb, r = bank.views[a], bank.views[b], res[(int(a), int(b))]
            dh = abs((va.heading_deg - vb.heading_deg + 180) % 360 - 180)
            base = float(np.linalg.norm(np.subtract(va.position, vb.position)))
            line = [f"{SNIPPETS[va.snippet]}/{va.path.name}@{va.offset}",
                    f"{SNIPPETS[vb.snippet]}/{vb.path.name}@{vb.offset}", va.row, vb.row, int(y[p]), bank.kind[p],
                    f"{dh:.2f}", f"{base:.2f}", f"{r.score:.4f}", f"{r.score_ransac:.4f}", f"{r.b_s:.5f}",
                    f"{r.b_d:.3f}"]
            if sift is not None:
                line.append(f"{scorers['SIFT (full image), NN'][p]:.5f}")
            w.writerow(line)

    # The real KITTI pairs of ../shared/data/pairs, through the same code path as `vslam horizon pairs`.
    pairs_csv = _kitti_pairs_csv(data_dir, args.out / "kitti_pairs.csv")
    scored = score_pairs_file(pairs_csv, args.out / "kitti_pairs_scores.csv", params)
    lab = np.array([int(r["label"]) for r in scored])
    pair_auc = {"1D SURF, NN": _auc_or_nan([r["score"] for r in scored], lab),
                "1D SURF, NN+RANSAC": _auc_or_nan([r["score_ransac"] for r in scored], lab)}
    print(f"KITTI pairs of ../shared/data/pairs ({int(lab.sum())} same place / {int((lab == 0).sum())} "
          f"different place, full 1226-px frames, row {KITTI_PAIR_ROW}): AUC NN {pair_auc['1D SURF, NN']:.3f}, "
          f"NN+RANSAC {pair_auc['1D SURF, NN+RANSAC']:.3f}")

    write_json(args.out / "horizon.json", {
        "benchmark": "horizon",
        "command": "vslam bench horizon " + " ".join(_argv_echo(args)),
        "params": params.to_dict(),
        "bank": {"views": len(bank.views), "matched": int(y.sum()), "unmatched": int((~y).sum()),
                 "kinds": {k: int((bank.kind == k).sum()) for k in np.unique(bank.kind)}, "seed": args.seed,
                 "snippets": list(SNIPPETS), "crop": bank.crop, "max_baseline_m": args.max_baseline,
                 "horizon_rows": sorted({v.row for v in bank.views})},
        "auc": aucs, "auc_by_subset": subsets, "auc_by_drive": by_drive, "auc_sweep": sweep_json,
        "auc_other_presets": compare_auc,
        "extraction_us_median": ext, "matching_us_median": mat, "mean_features": nfeat,
        "timing_calls": {"extraction": len(t_ext), "matching": len(t_match), "nn_only": len(t_nn),
                         "sift_extraction": len(sift.t_ext) if sift else 0,
                         "sift_matching": len(sift.t_match) if sift else 0},
        "sift_features_cap": args.sift_features, "opencv_threads": args.threads,
        "nn_ransac_at_5pct_fpr": {"tpr": tpr5, "threshold": thr5},
        "kitti_pairs": {"auc": pair_auc, "pairs": scored},
        "table": table, "sweep_table": sweep_table,
    })
    print(f"wrote {args.out / 'horizon.json'}, {args.out / 'roc.png'}, {args.out / 'bank_scores.csv'}")
    return 0


SCORE_NAMES = ("score", "score_ransac", "b_s", "b_d")


def _argv_echo(args: argparse.Namespace) -> list[str]:
    out = [f"--out {args.out}", f"--preset {args.preset}", f"--max-baseline {args.max_baseline:g}",
           f"--sweep {args.sweep}", f"--seed {args.seed}", f"--repeat {args.repeat}",
           f"--sift-features {args.sift_features}", f"--threads {args.threads}"]
    out += [f"--set {o}" for o in args.overrides]
    out += ["--no-sift"] if args.no_sift else []
    out += ["--quick"] if args.quick else []
    return out
