"""`vslam bench graph`: the pose-graph back end on public pose graphs.

Per dataset: size; solve time (LAGO + LM, or chordal + LM in 3D; LM from the odometry tree; one full iSAM2 pass)
as medians; final cost; the clean solution's error against ground truth where it exists. Then, with 10 / 30 / 50 %
extra random false loops (seeded; `graph.outliers.inject_false_loops`), plain least squares against the robust
default: trajectory error against the clean solution, that error over the dataset's error scale, loop precision /
recall and the share of injected loops labelled outliers. A method comparison (GNC, Cauchy, Huber, with and without
the gate and the settling rounds, gtsam's own GNC) runs on the same injected loops of the smaller graphs, and a
probability experiment compares the ways P(loop) can weight a loop.

Definitions (also in docs/graph.md):
- error vs clean = ATE RMSE of positions after a rigid (SE(2) / SE(3)) Umeyama alignment to the clean solution;
- error scale = the clean solution's ATE RMSE against ground truth when the dataset has it, else the RMS length of
  the odometry steps of the clean solution; the target is error vs clean <= 5 % of the scale;
- precision = true loops among the kept / kept; recall = true loops kept / true loops; "false rejected" = injected
  loops labelled outliers / injected.
Datasets that are absent are skipped with a note. Plain least squares on graphs with more than
--plain-lm-max-nodes nodes is skipped: random long-range loops make one Cholesky factorisation take minutes there
(measured in docs/benchmarks.md).
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import gtsam
import numpy as np

from graph import GraphParams, RobustMode, inject_false_loops, loop_scores, optimize, read_graph
from graph.incremental import gate_pass
from graph.initial import spanning_tree_guess
from vslam.bench.results import BenchResult, write_json
from vslam.bench.timing import median
from vslam.evaluation.metrics import umeyama
from vslam.evaluation.tables import format_table
from vslam.paths import shared_data_dir

QUICK = ("w100", "noisyToyGraph", "intel", "CSAIL")


@dataclass
class Dataset:
    name: str
    path: Path | None
    groundtruth: Path | None = None
    note: str = ""


def _datasets() -> list[Dataset]:
    wheel = Path(gtsam.__file__).parent / "Data"   # the example graphs shipped in gtsam's wheel
    shared = shared_data_dir()
    pg = shared / "posegraphs" if shared else None

    def w(name):
        return wheel / name if wheel else None

    def s(rel):
        return pg / rel if pg else None

    gt = "isam_with_groundtruth/groundtruth/"
    return [
        Dataset("w100", w("w100.graph")),
        Dataset("noisyToyGraph", w("noisyToyGraph.txt")),
        Dataset("w10000", w("w10000.graph")),
        Dataset("sphere2500", w("sphere2500.txt"), w("sphere2500_groundtruth.txt"), "3D"),
        Dataset("intel", s("se-sync/intel.g2o")),
        Dataset("CSAIL", s("se-sync/CSAIL.g2o"), None, "edges only"),
        Dataset("M3500", s("se-sync/2D/m3500.g2o"), s(gt + "manhattanOlson3500_groundtruth.txt")),
        Dataset("manhattan", s("se-sync/manhattan.g2o"), s(gt + "manhattanOlson3500_groundtruth.txt"),
                "M3500 with Olson's information, edges only"),
        Dataset("city10000", s("se-sync/city10000.g2o"), s(gt + "city10000_groundtruth.txt")),
        Dataset("garage", s("se-sync/parking-garage.g2o"), None, "3D"),
    ]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--datasets", help="comma-separated names (default: all present); "
                                      + ", ".join(d.name for d in _datasets()))
    p.add_argument("--quick", action="store_true", help=f"small graphs only ({', '.join(QUICK)}), one repetition, "
                                                        "50 %% outliers only, small comparison")
    p.add_argument("--fractions", default="0.1,0.3,0.5", help="false-loop fractions of the true loop count")
    p.add_argument("--seed", type=int, default=1, help="seed of the injected loops")
    p.add_argument("--repeat", type=int, default=3, help="repetitions of the timed clean solves (medians)")
    p.add_argument("--plain-lm-max-nodes", type=int, default=4000,
                   help="skip plain least squares on contaminated graphs larger than this")
    p.add_argument("--compare", default="intel,CSAIL",
                   help="datasets for the robust-method comparison at the largest fraction ('' to skip; on M3500 "
                        "the ungated methods take minutes each)")
    p.add_argument("--out", default="bench-results/graph.json", help="JSON output path")


# ------------------------------------------------------------------------------------------------------ helpers
def groundtruth_poses(path: Path, n: int):
    """Ground-truth poses from an iSAM / TORO edge file with perfect measurements: chain the odometry edges."""
    gt = read_graph(path)
    a, b = gt.edge_index_pairs()
    poses = spanning_tree_guess(gt, np.zeros(1, np.int64), np.full((1, gt.poses.shape[1]), np.nan), a, b)
    if len(poses) != n:
        raise ValueError(f"{path}: {len(poses)} ground-truth poses for {n} nodes")
    order = np.argsort(gt.node_ids)
    return poses[order]


def ate(ref, est, dim: int) -> float:
    """RMSE of positions after the rigid alignment of est onto ref."""
    x, y = est[:, :dim], ref[:, :dim]
    r, t, _ = umeyama(x, y)
    return float(np.sqrt(np.mean(np.sum((y - (x @ r.T + t)) ** 2, axis=1))))


def step_rms(poses, dim: int) -> float:
    return float(np.sqrt(np.mean(np.sum(np.diff(poses[:, :dim], axis=0) ** 2, axis=1))))


def _timed(fn, repeat: int):
    out, times = None, []
    for _ in range(max(1, repeat)):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, median(times), times


def _fmt_s(x) -> str:
    return "-" if x is None else (f"{x:.3f}" if x < 10 else f"{x:.1f}")


# ---------------------------------------------------------------------------------------------------- the runs
def clean_runs(ds: Dataset, data, repeat: int, log) -> dict:
    ls = GraphParams.preset("least_squares")
    init = "lago" if data.dim == 2 else "chordal"
    big = data.num_nodes > 5000
    log(f"  clean: {init} + LM x{repeat}")
    res, t_init, _ = _timed(lambda: optimize(data, ls, init=init), repeat)
    log(f"  clean: odometry + LM x{repeat}")
    res_odo, t_odo, _ = _timed(lambda: optimize(data, ls, init="odometry"), repeat)
    log(f"  clean: iSAM2 pass x{1 if big else repeat}")
    res_isam, t_isam, _ = _timed(lambda: optimize(data, ls, solver="isam2"), 1 if big else repeat)
    best = res if res.final_cost <= res_odo.final_cost else res_odo
    row = {"dataset": ds.name, "dim": data.dim, "nodes": data.num_nodes, "edges": data.num_edges,
           "loops": data.num_loops, f"{init}_lm_s": t_init, "init_s": res.init_seconds, "lm_iterations": res.iterations,
           "odometry_lm_s": t_odo, "odometry_lm_iterations": res_odo.iterations, "isam2_s": t_isam,
           "isam2_updates": res_isam.iterations, "cost_initial": res.initial_cost, "cost": best.final_cost,
           "cost_odometry_lm": res_odo.final_cost, "cost_isam2": res_isam.final_cost,
           "isam2_vs_lm_ate": ate(best.poses, res_isam.poses, data.dim), "chi2": 2.0 * best.final_cost,
           "step_rms": step_rms(best.poses, data.dim), "isam2_notes": res_isam.notes}
    if ds.groundtruth is not None and ds.groundtruth.exists():
        gt = groundtruth_poses(ds.groundtruth, data.num_nodes)
        row["ate_vs_groundtruth"] = ate(gt, best.poses, data.dim)
        row["scale"], row["scale_kind"] = row["ate_vs_groundtruth"], "clean ATE vs ground truth"
    else:
        row["scale"], row["scale_kind"] = row["step_rms"], "RMS odometry step"
    row["_clean_poses"] = best.poses
    row["_finite"] = bool(np.all(np.isfinite(best.poses)))
    return row


def outlier_runs(ds: Dataset, data, clean: dict, fractions, seed: int, plain_max: int, log) -> list[dict]:
    rows = []
    for f in fractions:
        dd, injected = inject_false_loops(data, f, seed)
        false_loop = injected[dd.is_loop]
        row = {"dataset": ds.name, "fraction": f, "injected": int(injected.sum())}
        runs = [("robust", GraphParams())]
        if data.num_nodes <= plain_max:
            runs.insert(0, ("plain", GraphParams.preset("least_squares").replace(lm_max_iterations=30)))
        else:
            row["plain_note"] = f"skipped: {data.num_nodes} nodes > --plain-lm-max-nodes"
        for tag, params in runs:
            log(f"  {int(round(f * 100))} % false loops: {tag}")
            t0 = time.perf_counter()
            res = optimize(dd, params)
            secs = time.perf_counter() - t0
            err = ate(clean["_clean_poses"], res.poses, data.dim)
            sc = loop_scores(res.loop_inlier, false_loop)
            row.update({f"{tag}_s": secs, f"{tag}_err": err, f"{tag}_err_ratio": err / clean["scale"],
                        f"{tag}_precision": sc.precision, f"{tag}_recall": sc.recall,
                        f"{tag}_false_rejected": sc.false_rejected, f"{tag}_cost": res.final_cost,
                        f"{tag}_notes": res.notes})
        rows.append(row)
    return rows


COMPARE_METHODS = [
    # name, params changes, what it is
    ("gnc (default)", {}, "gate + warm GNC-TLS + settling rounds"),
    ("cauchy", {"robust": "cauchy"}, "gate + Cauchy + settling rounds"),
    ("huber", {"robust": "huber"}, "gate + Huber + settling rounds"),
    ("gnc, no gate", {"gate_loops": False}, "warm GNC-TLS on all loops + settling rounds"),
    ("gnc only", {"gate_loops": False, "reinit_rounds": 0}, "warm GNC-TLS alone"),
    ("gnc-gm only", {"gate_loops": False, "reinit_rounds": 0, "gnc_loss": "gm"}, "warm GNC-GM alone"),
    ("gtsam gnc only", {"gate_loops": False, "reinit_rounds": 0, "gnc_impl": "gtsam"}, "gtsam.GncLMOptimizer"),
    ("cauchy only", {"robust": "cauchy", "gate_loops": False, "reinit_rounds": 0}, "Cauchy LM alone"),
    ("huber only", {"robust": "huber", "gate_loops": False, "reinit_rounds": 0}, "Huber LM alone"),
    ("gate only", {"robust": "none", "gate_loops": True}, "gate, then least squares on admitted loops"),
]


def compare_runs(ds: Dataset, data, clean: dict, fraction: float, seed: int, quick: bool, log) -> list[dict]:
    dd, injected = inject_false_loops(data, fraction, seed)
    false_loop = injected[dd.is_loop]
    rows = []
    methods = COMPARE_METHODS[:4] + COMPARE_METHODS[-1:] if quick else COMPARE_METHODS
    for name, changes, what in methods:
        params = GraphParams().replace(**changes)
        log(f"  compare {name}")
        t0 = time.perf_counter()
        if params.robust == RobustMode.NONE:          # "gate only": least squares on the admitted loops
            est, admitted = gate_pass(dd, params.replace(robust="gnc"))
            keep = dd.with_edges(~dd.is_loop | _expand(dd, admitted))
            keep.poses = est
            res = optimize(keep, params.replace(init="given"))
            inlier = admitted
        else:
            res = optimize(dd, params)
            inlier = res.loop_inlier
        secs = time.perf_counter() - t0
        err = ate(clean["_clean_poses"], res.poses, data.dim)
        sc = loop_scores(inlier, false_loop)
        rows.append({"dataset": ds.name, "fraction": fraction, "method": name, "what": what, "s": secs, "err": err,
                     "err_ratio": err / clean["scale"], "precision": sc.precision, "recall": sc.recall,
                     "false_rejected": sc.false_rejected})
    return rows


def _expand(data, per_loop):
    out = np.zeros(data.num_edges, bool)
    out[data.loop_edges()] = per_loop
    return out


def probability_runs(ds: Dataset, data, clean: dict, seed: int, log) -> list[dict]:
    """Equal numbers of true and false loops (fraction 1.0); P(loop) drawn informative but overlapping:
    true ~ U(0.5, 1), false ~ U(0.2, 0.9). Compares the ways the probability can enter."""
    dd, injected = inject_false_loops(data, 1.0, seed)
    rng = np.random.default_rng(seed + 1000)
    li = dd.loop_edges()
    false_loop = injected[li]
    p = np.where(false_loop, rng.uniform(0.2, 0.9, len(li)), rng.uniform(0.5, 1.0, len(li)))
    dd.probability[li] = p
    rows = []
    for weighting in ("none", "threshold", "information"):
        log(f"  probability: {weighting}")
        t0 = time.perf_counter()
        res = optimize(dd, GraphParams().replace(loop_weighting=weighting))
        secs = time.perf_counter() - t0
        sc = loop_scores(res.loop_inlier, false_loop)
        err = ate(clean["_clean_poses"], res.poses, data.dim)
        rows.append({"dataset": ds.name, "weighting": weighting, "s": secs, "err": err,
                     "err_ratio": err / clean["scale"], "precision": sc.precision, "recall": sc.recall,
                     "false_rejected": sc.false_rejected})
    return rows


# -------------------------------------------------------------------------------------------------------- main
def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _selection(args: argparse.Namespace) -> tuple[list[Dataset], list[float], int, list[str]]:
    """The datasets asked for, the false-loop fractions, the repetitions and the comparison datasets."""
    all_ds = _datasets()
    names = [d.name for d in all_ds]
    wanted = [s.strip() for s in args.datasets.split(",")] if args.datasets else (list(QUICK) if args.quick else names)
    unknown = [w for w in wanted if w not in names]
    if unknown:
        raise ValueError(f"--datasets: unknown dataset(s) {', '.join(unknown)}; known: {', '.join(names)}")
    fractions = [0.5] if args.quick else [float(x) for x in args.fractions.split(",") if x.strip()]
    compare = [c.strip() for c in args.compare.split(",") if c.strip()]
    if args.quick:
        compare = [c for c in compare if c in QUICK] or ["intel"]
    return [d for d in all_ds if d.name in wanted], fractions, 1 if args.quick else args.repeat, compare


def _measure(args, datasets: list[Dataset], fractions, repeat: int, compare) -> dict[str, list]:
    """Every run on every present dataset: rows per experiment, and the datasets skipped."""
    rows: dict[str, list] = {"skipped": [], "clean": [], "outliers": [], "compare": [], "probability": []}
    for ds in datasets:
        if ds.path is None or not ds.path.exists():
            rows["skipped"].append(f"{ds.name}: not found ({ds.path})")
            _log(f"skip {ds.name}: not found")
            continue
        _log(f"{ds.name}: {ds.path}")
        data = read_graph(ds.path)
        clean = clean_runs(ds, data, repeat, _log)
        rows["clean"].append(clean)
        if data.num_loops:
            rows["outliers"] += outlier_runs(ds, data, clean, fractions, args.seed, args.plain_lm_max_nodes, _log)
        if ds.name in compare and data.num_loops:
            rows["compare"] += compare_runs(ds, data, clean, max(fractions), args.seed, args.quick, _log)
        if ds.name == ("intel" if args.quick else "M3500") and data.num_loops:
            rows["probability"] += probability_runs(ds, data, clean, args.seed, _log)
    return rows


def _pct(x) -> str:
    return f"{100 * x:.1f}"


def _clean_table(rows) -> str:
    return format_table(
        ["dataset", "nodes", "edges", "loops", "LAGO/chordal + LM s", "LM from odometry s", "iSAM2 pass s",
         "iSAM2 updates", "final cost", "iSAM2 cost", "iSAM2 vs LM ATE", "ATE vs GT", "error scale"],
        [[r["dataset"] + (" (3D)" if r["dim"] == 3 else ""), r["nodes"], r["edges"], r["loops"],
          _fmt_s(r.get("lago_lm_s", r.get("chordal_lm_s"))), _fmt_s(r["odometry_lm_s"]), _fmt_s(r["isam2_s"]),
          r["isam2_updates"], f"{r['cost']:.6g}", f"{r['cost_isam2']:.6g}", f"{r['isam2_vs_lm_ate']:.2g}",
          f"{r['ate_vs_groundtruth']:.3g}" if "ate_vs_groundtruth" in r else "-",
          f"{r['scale']:.3g} ({'GT' if r['scale_kind'].startswith('clean') else 'step'})"] for r in rows])


def _outlier_table(rows) -> str:
    def plain(r, cell):
        return cell if "plain_err" in r else "-"

    return format_table(
        ["dataset", "false loops", "plain LM: err/scale", "precision", "recall", "false rej. %", "s",
         "robust: err/scale", "precision", "recall", "false rej. %", "s"],
        [[r["dataset"], f"{int(round(100 * r['fraction']))} % ({r['injected']})",
          f"{r['plain_err_ratio']:.3g}" if "plain_err" in r else "skipped",
          plain(r, f"{r.get('plain_precision', 0):.3f}"), plain(r, f"{r.get('plain_recall', 0):.3f}"),
          plain(r, _pct(r.get("plain_false_rejected", 0))), _fmt_s(r.get("plain_s")),
          f"{r['robust_err_ratio']:.3g}", f"{r['robust_precision']:.3f}", f"{r['robust_recall']:.3f}",
          _pct(r["robust_false_rejected"]), _fmt_s(r["robust_s"])] for r in rows])


def _method_table(rows, key: str, title: str) -> str:
    return format_table(["dataset", title, "err/scale", "precision", "recall", "false rej. %", "s"],
                        [[r["dataset"], r[key], f"{r['err_ratio']:.3g}", f"{r['precision']:.3f}",
                          f"{r['recall']:.3f}", _pct(r["false_rejected"]), _fmt_s(r["s"])] for r in rows])


def _report(args, tables: dict[str, str], fractions, skipped, total: float) -> str:
    """The text the benchmark prints (markdown)."""
    parts = ["## Clean graphs (times are medians of --repeat runs; iSAM2 on > 5000 nodes: one run)\n\n"
             + tables["clean"],
             f"## Injected false loops (seed {args.seed}); err = ATE vs the clean solution, scale as in column "
             "'error scale'; target err/scale <= 0.05\n\n" + tables["outliers"]]
    if tables["compare_rows"]:
        parts.append(f"## Robust methods on the same injected loops ({int(round(100 * max(fractions)))} %)\n\n"
                     + tables["compare"])
    if tables["probability_rows"]:
        parts.append("## Loop probability (as many false loops as true; p true ~ U(0.5, 1), false ~ U(0.2, 0.9))"
                     "\n\n" + tables["probability"])
    parts += [f"skipped {s}" for s in skipped]
    return "\n\n".join(parts + [f"total {total:.0f} s"])


def run(args: argparse.Namespace) -> BenchResult:
    datasets, fractions, repeat, compare = _selection(args)
    t_start = time.perf_counter()
    rows = _measure(args, datasets, fractions, repeat, compare)
    total = time.perf_counter() - t_start
    tables = {"clean": _clean_table(rows["clean"]), "outliers": _outlier_table(rows["outliers"]),
              "compare": _method_table(rows["compare"], "method", "method"),
              "probability": _method_table(rows["probability"], "weighting", "P(loop) weighting")}
    text = _report(args, {**tables, "compare_rows": rows["compare"], "probability_rows": rows["probability"]},
                   fractions, rows["skipped"], total)
    print(text)
    for r in rows["clean"]:
        r.pop("_clean_poses", None)
    write_json(args.out, {"benchmark": "graph", "seed": args.seed, "fractions": fractions, "repeat": repeat,
                          "quick": args.quick, "total_seconds": total, "skipped": rows["skipped"],
                          "clean": rows["clean"], "outliers": rows["outliers"], "compare": rows["compare"],
                          "probability": rows["probability"], "tables": tables})
    print(f"wrote {args.out}")
    # docs/benchmarks.md: without the run time, headings one level below the document's sections
    docs = text.rsplit("\n\ntotal ", 1)[0]
    return BenchResult("\n".join("#" + line if line.startswith("## ") else line for line in docs.split("\n")))
