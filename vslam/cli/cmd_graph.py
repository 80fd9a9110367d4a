"""`vslam graph optimize IN --out OUT.g2o`: optimise a g2o / TORO pose graph; `vslam graph info IN`: summarise it."""
from __future__ import annotations

import argparse

NAME = "graph"
HELP = "pose graphs: optimise a g2o / TORO file (robust loops, LM or iSAM2), or summarise one"
DESCRIPTION = ("Pose-graph back end. Loops are the edges between vertices that are not consecutive in the file's "
               "vertex order; odometry edges are trusted, loops are checked (--robust).")

PRESETS = ("default", "fast", "robust_strict", "least_squares")


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="graph_command", metavar="ACTION")
    sub.required = True
    o = sub.add_parser("optimize", help="optimise a pose graph and write it with every vertex id kept",
                       description="Optimise IN (g2o VERTEX_SE2/EDGE_SE2 or SE3:QUAT, or TORO VERTEX2/EDGE2) and "
                                   "write OUT (g2o, or TORO when it ends in .graph) with the input's ids, edge order, "
                                   "information matrices and comments.")
    o.add_argument("input", metavar="IN", help="g2o or TORO file")
    o.add_argument("--out", required=True, metavar="OUT", help="output graph (.g2o, or .graph for TORO)")
    o.add_argument("--robust", choices=("gnc", "huber", "cauchy", "none"), default=None,
                   help="loop outlier handling (default: the preset's, gnc)")
    o.add_argument("--solver", choices=("lm", "isam2"), default=None, help="batch LM or an iSAM2 pass (default lm)")
    o.add_argument("--init", choices=("auto", "lago", "odometry", "chordal", "given"), default=None,
                   help="initial guess for LM (default auto: LAGO / chordal without robust mode, else odometry)")
    o.add_argument("--preset", choices=PRESETS, default="default", help="GraphParams preset")
    o.add_argument("--tum", metavar="TRAJ", help="also write the optimised trajectory (TUM; timestamps = vertex ids)")
    o.add_argument("--labels", metavar="CSV", help="also write one row per loop: edge index, ids, inlier, weight, r2")
    o.set_defaults(func=run_optimize)
    i = sub.add_parser("info", help="count vertices, odometry edges and loops of a pose-graph file")
    i.add_argument("input", metavar="IN", help="g2o or TORO file")
    i.set_defaults(func=run_info)


def run(a: argparse.Namespace) -> int:  # pragma: no cover - argparse dispatches to the action
    return a.func(a)


def _describe(data) -> str:
    kind = "SE(2)" if data.dim == 2 else "SE(3)"
    no_guess = int((~data.has_pose).sum())
    return (f"{data.num_nodes} vertices ({kind}{f', {no_guess} without a guess' if no_guess else ''}), "
            f"{data.num_edges} edges: {data.num_edges - data.num_loops} odometry, {data.num_loops} loops")


def run_info(a: argparse.Namespace) -> int:
    from graph import read_graph

    data = read_graph(a.input)
    print(f"{a.input}: {_describe(data)}")
    if len(data.fixed):
        print(f"fixed vertices: {', '.join(str(i) for i in data.fixed.tolist())}")
    return 0


def run_optimize(a: argparse.Namespace) -> int:
    import numpy as np

    from graph import GraphParams, optimize, read_graph, write_graph
    from odometry.shared.atomic_io import atomic_write_text

    data = read_graph(a.input)
    params = GraphParams.preset(a.preset)
    res = optimize(data, params, solver=a.solver, robust=a.robust, init=a.init)
    write_graph(a.out, data, res.poses)
    print(f"{a.input}: {_describe(data)}")
    print(f"solver {res.solver}, robust {res.robust}, init {res.init}")
    print(f"cost {res.initial_cost:.6g} -> {res.final_cost:.6g}  ({res.iterations} iterations"
          f"{f', {res.gnc_iterations} GNC steps' if res.gnc_iterations else ''})")
    print(f"time {res.seconds:.3f} s (initial guess {res.init_seconds:.3f} s)")
    print(f"loops kept {res.loops_kept} / rejected {res.loops_rejected}")
    print(f"wrote {a.out}")
    if a.tum:
        res.write_tum(a.tum)
        print(f"wrote {a.tum}")
    if a.labels:
        rows = ["edge,from,to,inlier,weight,r2"]
        for e, ok, w, r2 in zip(res.loop_edges.tolist(), res.loop_inlier.tolist(), res.loop_weight.tolist(),
                                res.loop_residual.tolist()):
            rows.append(f"{e},{int(data.edge_from[e])},{int(data.edge_to[e])},{int(ok)},{w:.6g},{r2:.6g}")
        atomic_write_text(a.labels, "\n".join(rows) + "\n")
        print(f"wrote {a.labels}")
    return 0 if np.all(np.isfinite(res.poses)) else 1
