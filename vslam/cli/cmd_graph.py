"""`vslam graph optimize IN --out OUT.g2o`: optimise a g2o / TORO pose graph; `vslam graph info IN`: summarise it."""
from __future__ import annotations

import argparse
import sys

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
    o.add_argument("--robust", choices=("consensus", "gnc", "huber", "cauchy", "none"), default=None,
                   help="loop outlier handling (default: the preset's, consensus; gnc: the previous arrival gate + GNC)")
    o.add_argument("--solver", choices=("lm", "isam2"), default=None, help="batch LM or an iSAM2 pass (default lm)")
    o.add_argument("--init", choices=("auto", "lago", "odometry", "chordal", "given"), default=None,
                   help="initial guess for LM (default auto: LAGO / chordal without robust mode, else odometry)")
    o.add_argument("--preset", choices=PRESETS, default="default", help="GraphParams preset")
    o.add_argument("--config", metavar="FILE",
                   help="YAML / TOML / JSON with GraphParams settings (solver: / robust: / incremental:, or a pipeline "
                        "config's graph: section), applied on the preset")
    o.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting by its dotted key, e.g. --set robust.calibration_margin=5 (repeatable; "
                        "after --config; keys: python -c \"from graph import GraphParams; "
                        "print(GraphParams.describe())\")")
    o.add_argument("--print-config", action="store_true", help="print the effective GraphParams as YAML and exit")
    o.add_argument("--tum", metavar="TRAJ", help="also write the optimised trajectory (TUM; timestamps = vertex ids)")
    o.add_argument("--labels", metavar="CSV", help="also write one row per loop: edge index, ids, inlier, weight, r2")
    o.set_defaults(func=run_optimize)
    i = sub.add_parser("info", help="count vertices, odometry edges and loops of a pose-graph file")
    i.add_argument("input", metavar="IN", help="g2o or TORO file")
    i.set_defaults(func=run_info)


def run(a: argparse.Namespace) -> int:  # pragma: no cover - argparse dispatches to the action
    return a.func(a)


def run_info(a: argparse.Namespace) -> int:
    from vslam.app.graph import graph_file_info  # on use: keeps `vslam --help` fast (see vslam.cli.main)

    print(graph_file_info(a.input))
    return 0


def run_optimize(a: argparse.Namespace) -> int:
    from vslam.app.graph import graph_params, optimize_graph_file

    params = graph_params(a.preset, a.config, a.overrides)
    if a.print_config:
        print(params.dumps(), end="")
        return 0
    res = optimize_graph_file(a.input, a.out, solver=a.solver, robust=a.robust, init=a.init, tum=a.tum,
                              labels=a.labels, params=params)
    for w in res.warnings:
        print(f"vslam graph: warning: {w}", file=sys.stderr)
    print("\n".join(res.lines))
    return 0 if res.finite else 1
