"""Write a run's outputs: trajectories (TUM), loops.csv, graph.g2o, metrics.json, run.json, plots/."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from graph.formats import write_g2o
from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.tum import write_tum
from vslam.evaluation import plots
from vslam.evaluation.loops import RUN_LOOPS_HEADER
from vslam.evaluation.plots_loops import loop_status, plot_loop_matrix, similarity_matrix
from vslam.evaluation.run_eval import EVALUATION_PROBLEMS, evaluate_result, note_problem


def _fmt(v) -> str:
    if v is None:
        return ""
    if isinstance(v, (bool, np.bool_)):
        return "1" if v else "0"
    if isinstance(v, float):
        return "" if not np.isfinite(v) else f"{v:.6g}"
    return str(v)


def loops_csv_text(loops) -> str:
    lines = [",".join(RUN_LOOPS_HEADER)]
    for l in loops:
        lines.append(",".join(_fmt(v) for v in (l.query_frame, l.match_frame, l.global_score, l.local_score,
                                                l.probability, l.accepted, l.inlier)))
    return "\n".join(lines) + "\n"


def write_outputs(result, out_dir: str | Path, sequence=None, evaluate: bool = True, plots: bool = True,
                  bad_frames: list[dict] | None = None) -> Path:
    """All files of a run in `out_dir` (each written atomically). With a sequence that has ground truth, metrics.json
    also holds ATE/RPE (SE(2) alignment), the start-to-end error and loop precision/recall. `bad_frames` (frames
    that could not be read: index, file, problem) go into run.json and their count into metrics.json."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t = result.timestamps
    write_tum(out / "trajectory_vo.txt", t, result.poses_vo)
    write_tum(out / "trajectory_slam.txt", t, result.poses_slam)
    atomic_write_text(out / "loops.csv", loops_csv_text(result.loops))
    poses = result.graph_result.poses if result.graph_result is not None else None
    write_g2o(out / "graph.g2o", result.graph, poses)
    run_info = {"sequence": str(Path(result.sequence).resolve()) if result.sequence else None,
                "camera": result.camera.to_dict(), "keyframes": result.keyframes.tolist(),
                "loop_min_separation": int(result.config.database_params(result.camera).exclude_recent) + 1,
                "loop_exclude_seconds": float(result.config.database_params(result.camera).exclude_seconds),
                "loop_exclude_unleft": bool(result.config.database_params(result.camera).exclude_unleft),
                "config": result.config.to_dict(), "bad_frames": list(bad_frames or [])}
    atomic_write_text(out / "run.json", json.dumps(run_info, indent=1) + "\n")
    metrics = {"summary": {**result.summary(), "bad_frames": len(bad_frames or [])}}
    if result.graph_result is not None:
        g = result.graph_result
        metrics["graph"] = {"nodes": int(len(g.node_ids)), "loops_kept": g.loops_kept, "loops_rejected": g.loops_rejected,
                            "initial_cost": g.initial_cost, "final_cost": g.final_cost, "iterations": g.iterations,
                            "seconds": g.seconds}
    if evaluate and sequence is not None and sequence.groundtruth is not None:
        metrics["evaluation"] = evaluate_result(result, sequence)   # problems are warnings, listed in it
    if plots:
        try:
            _plots(result, out, sequence)
        except EVALUATION_PROBLEMS as exc:   # a plot must not cost the run's other files
            note_problem(metrics.setdefault("problems", []), "plots", exc)
    atomic_write_text(out / "metrics.json", json.dumps(metrics, indent=2, default=float) + "\n")
    return out


def _plots(result, out: Path, seq) -> None:
    pdir = out / "plots"
    pdir.mkdir(exist_ok=True)
    trajs = {}
    if seq is not None and seq.groundtruth is not None:
        trajs["ground truth"] = plots.start_anchored(seq.groundtruth_planar()[: len(result.timestamps)])
    trajs["VO"] = result.poses_vo
    trajs["SLAM"] = result.poses_slam
    p = result.poses_slam
    segs = {"accepted": [(p[l.query_frame], p[l.match_frame]) for l in result.loops if l.accepted and l.inlier],
            "outlier": [(p[l.query_frame], p[l.match_frame]) for l in result.loops if l.accepted and not l.inlier]}
    plots.plot_trajectories(pdir / "trajectories.png", trajs, loop_positions=segs,
                            title=f"{result.sequence}: trajectories (top view) and loop closures")
    marks = [(l.query_frame, l.match_frame, loop_status(l.accepted, l.inlier)) for l in result.loops]
    if len(result.keyframes) > 1:
        matrix = similarity_matrix(result.keyframes, result.similarity) if result.similarity else None
        plot_loop_matrix(pdir / "loop_scores.png", result.keyframes, matrix, marks,
                         title=f"{result.sequence}: retrieval similarity of each query keyframe to the stored ones")
    if seq is not None and seq.groundtruth is not None:
        gt = plots.start_anchored(seq.groundtruth_planar()[: len(result.timestamps)])
        ok = ~np.isnan(gt[:, 0])
        t = result.timestamps - result.timestamps[0]
        series = {name: (t[ok], np.linalg.norm(pp[ok, :2] - gt[ok, :2], axis=1))
                  for name, pp in (("VO", result.poses_vo), ("SLAM", result.poses_slam))}
        times = {"accepted": [t[l.query_frame] for l in result.loops if l.accepted and l.inlier],
                 "outlier": [t[l.query_frame] for l in result.loops if l.accepted and not l.inlier]}
        plots.plot_errors(pdir / "error_over_time.png", series, ylabel="position error, from a common start (m)",
                          loop_times=times, title=f"{result.sequence}: position error against ground truth")
