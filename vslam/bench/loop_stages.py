"""Where a run's loops are won and lost: every verified candidate of `vslam run`'s loop detection, by the stage that
decided it, grouped by its true footprint overlap J (ground truth).

The stages, in order: the detector's shortlist (`loops.csv` has a row per shortlisted, verified candidate), the
verifier's threshold (below it a candidate is never gated: "below threshold"), the motion gate (`GateResult.refused`:
no floor fit, outside the gate, the alias rule, the cluster rule, an ambiguous query), confirmation, acceptance, and
the back end (kept, or rejected as an outlier). Queries: those with a true revisit (`positive`, as evaluation counts
them, under the detector's own exclusions) and those whose shortlist held a candidate with J >= r at all.

    python -m vslam.bench.loop_stages SEQ [--mode 4] [--set loops.gate.refuse_ambiguous=false ...] [--vo-cache DIR]
"""
from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from odometry.shared.footprint import DEFAULT_OVERLAP_THRESHOLD, overlap_pairs
from vslam.bench.paper_runs import vo_pass
from vslam.evaluation.run_eval import evaluate_result
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig

STAGES = ("below threshold", "no fit", "motion", "alias", "cluster", "ambiguous", "unconfirmed",
          "rejected by back end", "kept")
GROUPS = ("J >= 0.33", "0 < J < 0.33", "J = 0")


def stage(loop, judged) -> str:
    """The stage that decided one verified candidate (a `LoopRecord`; `judged`: the gate's result or None)."""
    if loop.accepted:
        return "kept" if loop.inlier else "rejected by back end"
    if judged is None:
        return "below threshold"
    return judged.refused or "unconfirmed"


def loop_stages(seq, config: PipelineConfig, odometry=None) -> dict:
    """Run the pipeline (on `odometry`, a `Pipeline.odometry` pass, when given) and count its verified candidates
    per overlap group and stage; also the queries with a true revisit and those whose shortlist held one."""
    pipe = Pipeline(config)
    res = pipe.run(seq, odometry=odometry)
    gt = seq.groundtruth_planar()
    q = np.array([lp.query_frame for lp in res.loops], int)
    m = np.array([lp.match_frame for lp in res.loops], int)
    J = overlap_pairs(res.camera, gt[q], gt[m]) if len(q) else np.zeros(0)
    group = np.where(J >= DEFAULT_OVERLAP_THRESHOLD, GROUPS[0], np.where(J > 0, GROUPS[1], GROUPS[2]))
    results = {} if pipe.gate is None else pipe.gate.results
    stages = [stage(lp, results.get((lp.match_frame, lp.query_frame))) for lp in res.loops]
    counts = {g: Counter(s for s, gg in zip(stages, group) if gg == g) for g in GROUPS}
    ev = evaluate_result(res, seq)
    acc = ev.get("loops", {}).get("accepted", {})
    return {"counts": {g: dict(c) for g, c in counts.items()}, "candidates": int(len(q)),
            "keyframes": int(len(res.keyframes)), "positive_queries": int(acc.get("positive_queries", 0)),
            "queries_shortlisting_a_true_place": int(len(set(q[J >= DEFAULT_OVERLAP_THRESHOLD].tolist()))),
            "alias_distance_m": float(getattr(pipe.gate, "alias_distance", np.inf)),
            "vo_ate_m": ev["vo"]["ape_m"]["rmse"], "slam_ate_m": ev["slam"]["ape_m"]["rmse"]}


def table(out: dict) -> str:
    rows = [[g, str(sum(out["counts"][g].values()))] + [str(out["counts"][g].get(s, 0)) for s in STAGES]
            for g in GROUPS]
    return format_table(["true overlap", "verified candidates"] + list(STAGES), rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m vslam.bench.loop_stages", description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--mode", type=int, default=None, help="descriptor mode (default: the config's)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="config overrides, as `vslam run`")
    ap.add_argument("--vo-cache", type=Path, default=None,
                    help="reuse (or store) the VO pass as `vslam bench paper --vo-cache` does (the default VO config; "
                         "not with --set vo.* or fusion.*)")
    a = ap.parse_args(argv)
    if a.vo_cache is not None and any(k.split("=", 1)[0].split(".")[0] in ("vo", "fusion") for k in a.set):
        ap.error("--vo-cache holds the default VO's pass: drop it to change vo.* or fusion.*")
    cfg = PipelineConfig().with_overrides(a.set) if a.set else PipelineConfig()
    cfg = cfg.replace(recording=cfg.recording.replace(enabled=False))
    if a.mode is not None:
        cfg = cfg.replace(loops=cfg.loops.replace(mode=a.mode))
    vo = None if a.vo_cache is None else vo_pass(a.sequence, a.vo_cache).estimates
    out = loop_stages(open_sequence(a.sequence), cfg, odometry=vo)
    print(f"{a.sequence}: {out['keyframes']} keyframes, {out['candidates']} verified candidates; queries with a true "
          f"revisit {out['positive_queries']}, whose shortlist held a place with J >= 0.33 "
          f"{out['queries_shortlisting_a_true_place']}; alias distance {out['alias_distance_m']:.3f} m; "
          f"VO ATE {out['vo_ate_m']:.4f} m, SLAM ATE {out['slam_ate_m']:.4f} m\n")
    print(table(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
