"""`vslam bench descriptors`: the compact descriptor (modes 1-6) against OpenCV SIFT, as in seed 001 Tables I/V.

Measured in one run, single-threaded OpenCV for both (cv2.setNumThreads(1)):
  * bytes per image (mean / max), local features kept, extraction ms/image (640x480 simulated floors);
  * pairwise match ms (ours: full match incl. geometric check; SIFT: brute-force L2 kNN + ratio test only);
  * query ms against databases of 1k, 10k, 100k keyframes (real floor descriptors replicated with perturbed
    global descriptors; the shortlist is verified with real local descriptors);
  * loop precision / recall per floor at the learned thresholds (ground truth J >= r from the simulator's poses);
  * local-score matrices as PNG (seed 001 Fig. 2-3);
  * the 48 labelled real pairs in ../shared/data/pairs next to the MPEG reference software's figures.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from loops.cdvs import MODES, CdvsParams, decode, encode, load_trained, match
from loops.cdvs.codec import encode_all_modes
from loops.cdvs.database import DatabaseParams, LoopDatabase
from loops.cdvs.detector import detect_loops
from loops.cdvs.model import LoopModel
from loops.cdvs.plots import plot_score_matrices
from odometry.shared.footprint import overlap_pairs
from vslam.bench.results import BenchResult, write_json
from vslam.bench.timing import median, time_calls
from vslam.evaluation.loops import LoopTable, loop_precision_recall
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.paths import shared_data_dir
from vslam.sim.floor import FloorType
from vslam.sim.simulate import SimConfig, simulate
from vslam.sim.trajectory import TrajectoryKind

FLOORS = ("carpet", "concrete", "tiles", "wood", "printed-wood")
EXCLUDE_RECENT = 20   # keyframes never matched as loops (as `vslam loops` by default)
NATURAL = ("carpet", "concrete", "tiles", "wood")
# MPEG CDVS reference software (TM 14.2) on the 48 pairs, ../shared/notes/cdvs.md
CDVS_REFERENCE = {1: (512.0, 36, 67.3, 18), 2: (1024.1, 120, 67.1, 19), 3: (2048.6, 175, 67.9, 19),
                  4: (4092.9, 206, 69.6, 20), 5: (8141.0, 400, 85.4, 23), 6: (15651.2, 533, 93.8, 23)}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="bench-out/descriptors", help="output directory (JSON, PNG)")
    p.add_argument("--work", help="where simulated floors are rendered/cached (default OUT/floors)")
    p.add_argument("--model", help="loop model JSON (default: the shipped model)")
    p.add_argument("--quick", action="store_true", help="fewer floors, frames, sizes and repetitions (~3 min)")
    p.add_argument("--seed", type=int, default=1, help="simulation seed of the benchmark floors (training uses 201)")


# ------------------------------------------------------------------------------------------------ helpers
def _floors(work, quick: bool, seed: int):
    names = ("carpet", "tiles", "printed-wood") if quick else FLOORS
    out = {}
    for f in names:
        d = Path(work) / f"{f}-figure8-s{seed}{'-quick' if quick else ''}"
        if not (d / "frames.csv").is_file():
            cfg = SimConfig(floor=FloorType(f), trajectory=TrajectoryKind("figure8"), laps=2,
                            length=5.0 if quick else 8.0, fps=10.0, seed=seed)
            simulate(cfg, d, overwrite=True)
        out[f] = d
    return out


def _sift_bytes(n: int) -> int:
    return n * (128 * 4 + 2 * 4)  # float32 descriptors + float32 (x, y), as OpenCV holds them


class _Log:
    """Stage lines on stderr with the seconds since the start."""

    def __init__(self) -> None:
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        print(f"[{self.seconds:6.0f} s] {msg}", file=sys.stderr)

    @property
    def seconds(self) -> float:
        return time.perf_counter() - self.t0


# ------------------------------------------------------------------------------------------------ stages
def sizes_and_extraction(seqs: dict, floor_params: dict, trained, quick: bool) -> tuple[dict, dict]:
    """Per mode: bytes per image (mean / max), budget, local features, extraction ms; the same for SIFT."""
    n_img = 6 if quick else 16
    sample = {f: [s.image(int(i), gray=True) for i in np.linspace(0, len(s) - 1, n_img).astype(int)]
              for f, s in seqs.items()}
    images = [im for ims in sample.values() for im in ims]
    rep = 2 if quick else 3
    per_mode: dict[int, dict] = {}
    for m in MODES:
        p = floor_params[m]
        sizes, nloc, ms = [], [], []
        for im in images:
            data = encode(im, m, p, trained)
            sizes.append(len(data))
            nloc.append(decode(data).n_local)
            ms.append(median(time_calls(lambda: encode(im, m, p, trained), repeat=rep, warmup=1)) * 1e3)
        per_mode[m] = {"bytes_mean": float(np.mean(sizes)), "bytes_max": int(max(sizes)), "budget": p.mode.budget,
                       "n_local_mean": float(np.mean(nloc)), "extract_ms": median(ms)}
    sift = cv2.SIFT_create()
    s_n, s_ms = [], []
    for im in images:
        kp, _ = sift.detectAndCompute(im, None)
        s_n.append(len(kp))
        s_ms.append(median(time_calls(lambda: sift.detectAndCompute(im, None), repeat=1, warmup=0)) * 1e3)
    sift_stats = {"bytes_mean": float(np.mean([_sift_bytes(n) for n in s_n])),
                  "bytes_max": int(max(_sift_bytes(n) for n in s_n)), "n_local_mean": float(np.mean(s_n)),
                  "extract_ms": median(s_ms)}
    return per_mode, sift_stats


def _pair_indices(seqs: dict, quick: bool) -> list[tuple[str, int, int]]:
    pair_idx = []
    for f, s in seqs.items():
        n = len(s)
        for i in np.linspace(0, n - 12, 4 if quick else 8).astype(int):
            pair_idx.append((f, int(i), int(i) + 6))                 # overlapping
            pair_idx.append((f, int(i), int((i + n // 2) % n)))       # usually disjoint
    return pair_idx


def pairwise_matching(seqs: dict, floor_params: dict, trained, quick: bool, per_mode: dict, sift_stats: dict) -> dict:
    """Median pairwise match ms per mode (into per_mode) and for SIFT kNN + ratio test (into sift_stats); returns
    the decoded descriptors of the frames used, by (floor, frame) and mode."""
    pair_idx = _pair_indices(seqs, quick)
    needed = {(f, i) for f, i, _ in pair_idx} | {(f, j) for f, _, j in pair_idx}
    sift = cv2.SIFT_create()
    descs, sift_desc = {}, {}
    for f, i in sorted(needed):
        im = seqs[f].image(i, gray=True)
        enc = encode_all_modes(im, MODES, floor_params, trained)
        descs[(f, i)] = {m: decode(b) for m, b in enc.items()}
        sift_desc[(f, i)] = sift.detectAndCompute(im, None)[1]
    bf = cv2.BFMatcher(cv2.NORM_L2)

    def sift_match(da, db):
        knn = bf.knnMatch(da, db, k=2)
        return [p[0] for p in knn if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]

    rep = 5 if quick else 15
    for m in MODES:
        mp = floor_params[m].matching
        t = [median(time_calls(lambda: match(descs[(f, i)][m], descs[(f, j)][m], mp, trained), repeat=rep))
             for f, i, j in pair_idx]
        per_mode[m]["match_ms"] = median(t) * 1e3
    t = [median(time_calls(lambda: sift_match(sift_desc[(f, i)], sift_desc[(f, j)]), repeat=2, warmup=1))
         for f, i, j in pair_idx]
    sift_stats["match_ms"] = median(t) * 1e3
    return descs


def _synthetic(d, rng):
    """A copy of a descriptor with about a quarter of its global bits flipped (a distinct database entry)."""
    flip = rng.integers(0, 2 ** 32, size=d.global_bits.shape, dtype=np.uint64).astype(np.uint32)
    flip &= rng.integers(0, 2 ** 32, size=d.global_bits.shape, dtype=np.uint64).astype(np.uint32)
    return type(d)(**{**d.__dict__, "global_bits": np.where(d.global_visited, d.global_bits ^ flip, 0)
                      .astype(np.uint32)})


def query_scaling(descs: dict, floor_params: dict, trained, model, sizes_db, quick: bool) -> dict[int, dict]:
    """Query ms per mode against databases of each size (real descriptors replicated with perturbed globals)."""
    base = [descs[k] for k in sorted(descs)]
    rng = np.random.default_rng(0)
    query_ms: dict[int, dict[int, float]] = {m: {} for m in MODES}
    for m in MODES:
        for n_db in sizes_db:
            db = LoopDatabase(m, floor_params[m], DatabaseParams(shortlist=5, exclude_recent=0), trained=trained,
                              threshold=model.threshold(m))
            for k in range(n_db):
                db.add(k, _synthetic(base[k % len(base)][m], rng))
            queries = [base[(k * 7 + 3) % len(base)][m] for k in range(8 if quick else 20)]
            t = [median(time_calls(lambda: db.query(qd), repeat=3, warmup=1)) for qd in queries]
            query_ms[m][n_db] = median(t) * 1e3
    return query_ms


def loops_per_floor(seqs: dict, floor_params: dict, model, trained, exclude_recent: int, log) -> dict[str, dict]:
    """Loop precision / recall per floor and mode at the model's thresholds, against footprint ground truth."""
    loops_pr: dict[str, dict[int, dict]] = {}
    for f, s in seqs.items():
        gt = s.groundtruth_planar()
        loops_pr[f] = {}
        imgs = [s.image(i, gray=True) for i in range(len(s))]
        for m in MODES:
            rows, _ = detect_loops(list(enumerate(imgs)), m, floor_params[m],
                                   DatabaseParams(shortlist=5, exclude_recent=exclude_recent), model=model,
                                   trained=trained)
            qf = np.array([r.query_frame for r in rows], dtype=int)
            mf = np.array([r.candidate.frame_id for r in rows], dtype=int)
            acc = np.array([r.candidate.accepted for r in rows], dtype=bool)
            table = LoopTable(qf, mf, np.zeros(len(rows)), np.array([r.candidate.local_score for r in rows]),
                              np.zeros(len(rows)), acc, None)
            pr = loop_precision_recall(s.camera, gt, table, queried=np.arange(len(s)),
                                       r=model.overlap_threshold, min_separation=exclude_recent)
            jacc = overlap_pairs(s.camera, gt[qf[acc]], gt[mf[acc]]) if acc.any() else np.zeros(0)
            pr["wrong_place"] = int(np.sum(jacc <= 0.0))   # accepted loops whose footprints do not overlap at all
            loops_pr[f][m] = pr
        log(f"loop detection on {f} done")
    return loops_pr


def score_matrices(seqs: dict, floor_params: dict, trained, out: Path, quick: bool) -> None:
    """Local-score matrices as PNG (seed 001 Fig. 2-3): every floor at mode 6, printed wood at every mode."""
    step = 6 if quick else 3
    mats_f, mats_w = {}, {}
    for f, s in seqs.items():
        idx = np.arange(0, len(s), step)
        modes_here = MODES if f == "printed-wood" else (6,)
        enc = [encode_all_modes(s.image(int(i), gray=True), modes_here,
                                {m: floor_params[m] for m in modes_here}, trained) for i in idx]
        for m in modes_here:
            ds = [decode(e[m]) for e in enc]
            mat = np.zeros((len(ds), len(ds)))
            for i in range(len(ds)):
                for j in range(i):
                    mat[i, j] = match(ds[i], ds[j], floor_params[m].matching, trained).local_score
            if m == 6:
                mats_f[f] = mat
            if f == "printed-wood":
                mats_w[f"mode {m}"] = mat
    plot_score_matrices(mats_f, out / "score_matrices_floors_mode6.png", "local score, mode 6 (row: query, col: earlier)")
    if mats_w:
        plot_score_matrices(mats_w, out / "score_matrices_printed_wood.png", "printed wood: local score per mode")


def real_pairs(trained, quick: bool) -> dict[int, dict] | None:
    """The 48 labelled real pairs of ../shared/data/pairs per mode (None when the folder is absent)."""
    shared = shared_data_dir()
    if shared is None or not (shared / "pairs" / "pairs.txt").is_file():
        return None
    pdir = shared / "pairs"
    pairs = [ln.split() for ln in (pdir / "pairs.txt").read_text().splitlines() if ln.strip()]
    names = sorted({n for x, y, _ in pairs for n in (x, y)})
    pimgs = {n: cv2.imread(str(pdir / "images" / f"{n}.png"), cv2.IMREAD_GRAYSCALE) for n in names}
    real = {}
    for m in MODES:
        p = CdvsParams.for_mode(m)
        ds = {n: decode(encode(pimgs[n], m, p, trained)) for n in names}
        ext = [median(time_calls(lambda: encode(pimgs[n], m, p, trained), repeat=2 if quick else 5, warmup=1))
               for n in names]
        lt, gt_ = trained.local_threshold[m - 1], trained.global_threshold[m - 1]
        acc = {"1": 0, "0": 0}
        for x, y, lab in pairs:
            r = match(ds[x], ds[y], p.matching, trained)
            acc[lab] += int(r.local_score >= lt or r.global_score >= gt_)
        sz = [d.nbytes for d in ds.values()]
        real[m] = {"same_accepted": acc["1"], "diff_accepted": acc["0"], "bytes_mean": float(np.mean(sz)),
                   "bytes_min": int(min(sz)), "bytes_max": int(max(sz)),
                   "n_local_mean": float(np.mean([d.n_local for d in ds.values()])),
                   "extract_ms_mean": float(np.mean(ext)) * 1e3,
                   "local_threshold": float(lt), "global_threshold": float(gt_)}
    return real


# ------------------------------------------------------------------------------------------------ tables
def size_table(per_mode: dict, sift_stats: dict, sizes_db) -> str:
    head = ["mode", "budget B", "bytes mean / max", "local features", "extract ms", "match ms",
            *[f"query ms @{n // 1000}k" for n in sizes_db], "storage vs SIFT", "match vs SIFT per pair",
            f"query vs SIFT scan @{sizes_db[-1] // 1000}k"]
    rows = []
    for m in MODES:
        r = per_mode[m]
        rows.append([m, r["budget"], f"{r['bytes_mean']:.0f} / {r['bytes_max']}", f"{r['n_local_mean']:.0f}",
                     f"{r['extract_ms']:.2f}", f"{r['match_ms']:.3f}",
                     *[f"{r['query_ms'][n]:.2f}" for n in sizes_db],
                     f"{sift_stats['bytes_mean'] / r['bytes_mean']:.0f}x",
                     f"{sift_stats['match_ms'] / r['match_ms']:.0f}x",
                     f"{sift_stats['match_ms'] * sizes_db[-1] / r['query_ms'][sizes_db[-1]]:.0f}x"])
    rows.append(["SIFT", "-", f"{sift_stats['bytes_mean']:.0f} / {sift_stats['bytes_max']}",
                 f"{sift_stats['n_local_mean']:.0f}", f"{sift_stats['extract_ms']:.2f}",
                 f"{sift_stats['match_ms']:.3f}",
                 *[f"~{sift_stats['match_ms'] * n / 1000:.0f} s (linear scan)" for n in sizes_db], "1x", "1x", "1x"])
    return format_table(head, rows)


def loops_table(loops_pr: dict, model) -> str:
    names = list(loops_pr)
    rows = []
    for m in MODES:
        cells = []
        for f in names:
            pr = loops_pr[f][m]
            prec = pr["precision"]   # one decimal below 100 %: a single false loop must not round away
            ptxt = "-" if prec != prec else ("100%" if pr["false_positives"] == 0 else f"{100 * prec:.1f}%")
            cells.append(f"{ptxt} / {100 * pr['recall']:.0f}% ({pr['false_positives']} / {pr['wrong_place']})")
        rows.append([m, *cells, f"{model.threshold(m):.3g}"])
    return format_table(["mode", *[f"{f} P / R (false / wrong place)" for f in names], "threshold"], rows)


def real_pairs_table(real: dict) -> str:
    head = ["mode", "bytes mean [min-max]", "local features", "extract ms (mean)", "same-scene accepted",
            "different-scene accepted", "CDVS ref: same / diff", "CDVS ref extract ms", "speed-up"]
    rows = [[m, f"{r['bytes_mean']:.0f} [{r['bytes_min']}-{r['bytes_max']}]", f"{r['n_local_mean']:.0f}",
             f"{r['extract_ms_mean']:.1f}", f"{r['same_accepted']}/28", f"{r['diff_accepted']}/20",
             f"{CDVS_REFERENCE[m][3]}/28, 0/20", f"{CDVS_REFERENCE[m][2]:.1f}",
             f"{CDVS_REFERENCE[m][2] / r['extract_ms_mean']:.1f}x"] for m, r in real.items()]
    return format_table(head, rows)


# ------------------------------------------------------------------------------------------------ the benchmark
def _measure(a: argparse.Namespace, out: Path, log: _Log) -> dict:
    """Every stage, single-threaded OpenCV; returns the results by stage."""
    q = a.quick
    trained = load_trained()
    model = LoopModel.load(a.model) if a.model else LoopModel.default()
    floor_params = {m: CdvsParams.floor(m) for m in MODES}
    floors = _floors(Path(a.work) if a.work else out / "floors", q, a.seed)
    seqs = {f: open_sequence(d) for f, d in floors.items()}
    log(f"floors ready: {', '.join(f'{f} ({len(s)} frames)' for f, s in seqs.items())}")
    per_mode, sift_stats = sizes_and_extraction(seqs, floor_params, trained, q)
    log("sizes and extraction timed")
    descs = pairwise_matching(seqs, floor_params, trained, q, per_mode, sift_stats)
    log("pairwise matching timed")
    sizes_db = (1000, 10000) if q else (1000, 10000, 100000)
    for m, ms in query_scaling(descs, floor_params, trained, model, sizes_db, q).items():
        per_mode[m]["query_ms"] = ms
    log("query scaling timed")
    loops_pr = loops_per_floor(seqs, floor_params, model, trained, EXCLUDE_RECENT, log)
    score_matrices(seqs, floor_params, trained, out, q)
    log("score matrices written")
    real = real_pairs(trained, q)
    if real is not None:
        log("48 real pairs done")
    return {"modes": per_mode, "sift": sift_stats, "loops": loops_pr, "real_pairs": real, "floors": floors,
            "sizes_db": sizes_db, "model": model}


def run(a: argparse.Namespace) -> BenchResult:
    log = _Log()
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    r = _measure(a, out, log)
    cv2.setNumThreads(threads)
    text = ("### Size and speed (simulated 640x480 floors, single-threaded)\n\n"
            + size_table(r["modes"], r["sift"], r["sizes_db"])
            + "\n\n### Loops at the learned thresholds (precision / recall over queries; false loops / wrong-place "
            "loops)\n\n" + loops_table(r["loops"], r["model"])
            + ("\n\n### 48 real pairs (../shared/data/pairs)\n\n" + real_pairs_table(r["real_pairs"])
               if r["real_pairs"] else "") + "\n")
    print(text)
    result = {"quick": a.quick, "seed": a.seed, "opencv_threads": 1, "modes": r["modes"], "sift": r["sift"],
              "loops": r["loops"], "real_pairs": r["real_pairs"], "floors": {f: str(d) for f, d in r["floors"].items()},
              "exclude_recent": EXCLUDE_RECENT, "model": str(a.model) if a.model else "default",
              "seconds": log.seconds,
              "query_database": "real floor descriptors replicated; global bits perturbed (~25 % flipped)"}
    write_json(out / "descriptors.json", json.loads(json.dumps(result, default=float)))
    (out / "descriptors.md").write_text(text)
    log(f"wrote {out / 'descriptors.json'}")
    return BenchResult(text)
