"""`vslam bench graph`: robust pose-graph optimisation on public graphs with Vertigo-style false loops.

For every graph (vslam.bench.graph_data), outlier policy (random, local, random-grouped, local-grouped; see
vslam.bench.graph_outliers), fraction of false loops (of the true loop count) and seed, the methods of
vslam.bench.graph_methods run on the same contaminated graph: ours (`graph.RobustPoseGraph`, the default
parameters), GTSAM's GncLMOptimizer with the odometry as known inliers, DCS on GTSAM, DCS on g2o (child process),
plain LM. Each (graph, policy, fraction, seed, method) is one row (vslam.bench.graph_rows): `--out FILE` is rewritten
atomically after every row, a rerun with the same file skips the rows already there (same code version), and
`--jobs N` solves rows in N processes.

Metrics per row: ATE = RMSE of positions after a rigid alignment, against ground truth where the graph has it,
else against the converged clean optimum (vslam.bench.graph_reference: plain LM on the clean graph run to
convergence, cached next to the output); `ate_opt` is always against the converged clean optimum; true loops kept
(share of the graph's own loops labelled inlier); false loops rejected (share of the injected ones labelled
outlier); seconds. Tables and targets: vslam.bench.graph_tables.

Tuning / reporting split: the defaults of the robust method were chosen on the tuning graphs with the tuning seeds
(`graph_data.TUNING_GRAPHS`, `TUNING_SEEDS`); every other graph and seed is reporting only. Rows say which.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from vslam.bench import graph_methods
from vslam.bench import graph_rows as rows_
from vslam.bench.graph_data import QUICK_GRAPHS, TUNING_GRAPHS, TUNING_SEEDS, datasets
from vslam.bench.graph_outliers import POLICIES
from vslam.bench.graph_rows import RowStore, code_version, execute, graph_heads, head, log, plan, row_key
from vslam.bench.graph_tables import tables
from vslam.bench.results import BenchResult

FULL_FRACTIONS = "0,0.1,0.3,0.5"
QUICK_FRACTIONS = "0,0.3,0.5"
STRETCH_FRACTIONS = (0.7, 0.8)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--full", action="store_true",
                   help="every graph, fractions " + FULL_FRACTIONS + ", seeds 1,2,3 (default: the quick set: "
                        + ", ".join(QUICK_GRAPHS) + "; fractions " + QUICK_FRACTIONS + "; seed 1)")
    p.add_argument("--datasets", help="comma-separated graph names (overrides the set); known: "
                                      + ", ".join(d.name for d in datasets()))
    p.add_argument("--policies", default=",".join(POLICIES), help="outlier policies")
    p.add_argument("--fractions", help="false-loop fractions of the true loop count (overrides the set)")
    p.add_argument("--stretch", action="store_true", help="also 70 and 80 %% false loops")
    p.add_argument("--seeds", help="comma-separated seeds (overrides the set)")
    p.add_argument("--methods", default=",".join(m for m in graph_methods.METHODS if not m.startswith(("ours-own", "ours-refine"))),
                   help="methods: " + ", ".join(graph_methods.METHODS))
    p.add_argument("--peer-max-nodes", type=int, default=4000,
                   help="run " + ", ".join(graph_methods.PEERS_LIMITED) + " on contaminated graphs only up to this "
                        "many nodes (gtsam's GNC restarts every inner solve, g2o's LM with DCS rejects most steps: "
                        "minutes per row on 10^4 nodes)")
    p.add_argument("--peer-timeout", type=float, default=0.0, metavar="SECONDS",
                   help="stop a row of " + ", ".join(graph_methods.PEERS_LIMITED) + " after this many seconds and "
                        "report it as a timeout (0: no limit; needs --jobs 1)")
    p.add_argument("--from-json", help="comma-separated JSON files of earlier runs: print (and publish) their tables "
                                       "together instead of solving (later files win on the same row)")
    p.add_argument("--out", default="bench-results/graph.json",
                   help="JSON output, rewritten atomically after every row; a rerun with the same file skips the "
                        "rows already there (the converged references are cached in its folder, graph-reference/)")
    p.add_argument("--jobs", type=int, default=1, help="rows solved in this many processes (one graph in memory "
                                                       "each; timings are then under each other's load)")
    p.add_argument("--order", choices=("graph", "priority"), default="graph",
                   help="graph: graph by graph; priority: method by method in --methods order, each over every "
                        "graph at 0, 50, 30, 10 %% false loops, stretch last (a run cut short keeps the telling rows)")
    p.add_argument("--redo-stale", action="store_true",
                   help="redo rows made by another code version (default: keep them, marked stale in the tables)")


def _selection(args):
    names = [d.name for d in datasets()]
    if args.datasets:
        wanted = [s.strip() for s in args.datasets.split(",") if s.strip()]
    else:
        wanted = names if args.full else list(QUICK_GRAPHS)
    unknown = [w for w in wanted if w not in names]
    if unknown:
        raise ValueError(f"--datasets: unknown graph(s) {', '.join(unknown)}; known: {', '.join(names)}")
    fr = args.fractions or (FULL_FRACTIONS if args.full else QUICK_FRACTIONS)
    fractions = [float(x) for x in fr.split(",") if x.strip()] + (list(STRETCH_FRACTIONS) if args.stretch else [])
    seeds = [int(x) for x in (args.seeds or ("1,2,3" if args.full else "1")).split(",") if x.strip()]
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    bad = [p for p in policies if p not in POLICIES]
    if bad:
        raise ValueError(f"--policies: unknown {', '.join(bad)}; known: {', '.join(POLICIES)}")
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in graph_methods.METHODS]
    if bad:
        raise ValueError(f"--methods: unknown {', '.join(bad)}; known: {', '.join(graph_methods.METHODS)}")
    by_name = {d.name: d for d in datasets()}
    return [by_name[w] for w in dict.fromkeys(wanted)], policies, fractions, seeds, methods   # in the order asked


def _split_note() -> str:
    return (f"Tuning half: graphs {', '.join(TUNING_GRAPHS)} with seed(s) {', '.join(map(str, TUNING_SEEDS))}; every "
            "other graph and seed reports.")


def merged(paths: list[str]) -> BenchResult:
    """The tables of earlier runs' JSON files together (graphs in file order; a later file wins on the same row)."""
    heads: dict[str, dict] = {}
    rows: dict[tuple, dict] = {}
    for path in paths:
        d = json.loads(Path(path).read_text())
        heads.update(graph_heads(d))
        for r in d["rows"]:
            rows[row_key(r)] = r
    rs = list(rows.values())
    commits = sorted({r.get("commit", "?") for r in rs})
    text = (f"Rows from {', '.join(Path(p).name for p in paths)}: {len(rs)} rows, commit(s) {', '.join(commits)}. "
            + _split_note() + "\n\n" + tables(heads, rs, code_version()))
    print(text)
    return BenchResult(text)


def run(args: argparse.Namespace) -> BenchResult:
    if args.from_json:
        return merged([p.strip() for p in args.from_json.split(",") if p.strip()])
    sel, policies, fractions, seeds, methods = _selection(args)
    t0 = time.perf_counter()
    out = Path(args.out)
    ref_dir = str(out.parent / "graph-reference")
    store = RowStore(out)
    version = code_version()
    present = []
    for ds in sel:
        if ds.path is None or not ds.path.exists():
            log(f"skip {ds.name}: not found ({ds.path})")
            continue
        h = store.graphs.get(ds.name)
        if h is None or h.get("version") != version:
            h = {**head(ds.name, ref_dir), "version": version}
            store.set_graph(h)
        log(f"{ds.name}: {h['nodes']} nodes, {h['loops']} loops; converged reference {h['ref_iterations']} "
            f"iterations, ATE {h['ref_ate']:.4g}; plain LM (default) ATE {h['clean_ate']:.4g}")
        present.append(ds.name)
    nodes = {g: store.graphs[g]["nodes"] for g in present}
    tasks = plan(present, nodes, policies, fractions, seeds, methods, args.peer_max_nodes)
    todo = [t for t in tasks if not store.done(t, version) and (args.redo_stale or not store.present(t))]
    if args.order == "priority":
        todo = rows_.priority_order(todo, methods)
    log(f"{len(tasks)} rows selected, {len(tasks) - len(todo)} already in {out}, {len(todo)} to solve "
        f"({args.jobs} job(s))")

    def on_row(r: dict) -> None:
        store.add(r)
        f = int(round(100 * r["fraction"]))
        what = (f"ATE {r['ate']:.4g} kept {100 * r['true_kept']:.1f} % rejected {100 * r['false_rejected']:.1f} % "
                f"{r['s']:.2f} s") if r["status"] == "ok" else f"{r['status']}: {r.get('error', '')}"
        log(f"  {r['graph']:10s} {r['policy']:14s} {f:3d} % seed {r['seed']} {r['method']:10s} {what}")

    execute(todo, ref_dir, args.jobs, on_row, args.peer_timeout)
    total = time.perf_counter() - t0
    rows = [r for r in store.rows.values() if r["graph"] in present]
    text = (f"Rows of {out.name} for {', '.join(present)} ({len(rows)} rows). " + _split_note() + "\n\n"
            + tables({g: store.graphs[g] for g in present}, rows, version))
    print(text)
    print(f"\ntotal {total:.0f} s; {len(todo)} rows solved; wrote {out}")
    return BenchResult(text)


