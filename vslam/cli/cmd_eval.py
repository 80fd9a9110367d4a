"""`vslam eval OUT`: ATE/RPE (evo conventions), start-to-end error, loop precision/recall, plots."""
from __future__ import annotations

import argparse

NAME = "eval"
HELP = "evaluate a run directory against ground truth (ATE/RPE as evo, loops, plots)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out", help="run directory (trajectory_vo.txt / trajectory_slam.txt, loops.csv, run.json)")
    p.add_argument("--gt", help="ground truth TUM file (default: the sequence's groundtruth.txt via run.json)")
    p.add_argument("--align", default="se3", choices=["none", "se2", "se3", "sim3"],
                   help="alignment before ATE (Umeyama; se2 = rotation about z + xy translation)")
    p.add_argument("--delta", type=float, default=1.0, help="RPE delta (default 1)")
    p.add_argument("--delta-unit", default="f", choices=["f", "m"], help="RPE delta in frames or metres")
    p.add_argument("--max-diff", type=float, default=0.01, help="max timestamp difference for association (s)")
    p.add_argument("--overlap", type=float, default=0.33, help="footprint overlap J for a true loop (seed 001: 0.33)")
    p.add_argument("--no-plots", action="store_true")


def run(a: argparse.Namespace) -> int:
    from vslam.evaluation.run_eval import evaluate_run, format_report

    rep = evaluate_run(a.out, gt_file=a.gt, alignment=a.align, delta=a.delta, delta_unit=a.delta_unit,
                       max_diff=a.max_diff, overlap_threshold=a.overlap, make_plots=not a.no_plots)
    print(format_report(rep))
    print(f"wrote {a.out}/eval.json" + ("" if a.no_plots else f" and {a.out}/plots/"))
    return 0
