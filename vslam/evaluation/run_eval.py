"""Evaluate a SLAM run against ground truth: a run directory written by `vslam run` (or any folder with TUM
trajectories), or a pipeline result in memory beside its sequence."""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.camera import CameraModel
from odometry.shared.errors import ToolkitError
from odometry.shared.tum import read_tum, se2_to_tum, tum_to_se2, tum_to_se3_matrices
from vslam.errors import SkippedInputWarning, VslamError
from vslam.evaluation import plots
from vslam.evaluation.loops import LoopTable, loop_precision_recall, read_loops_csv
from vslam.evaluation.metrics import Alignment, DeltaUnit, align, associate, evaluate, start_to_end_error
from vslam.evaluation.plots_loops import loop_status, plot_loop_matrix, similarity_matrix
from vslam.io import open_sequence
from vslam.sequence import Trajectory

TRAJECTORIES = {"VO": "trajectory_vo.txt", "SLAM": "trajectory_slam.txt"}
# What makes an evaluation impossible without the run being wrong: too few frames, ground truth that barely moves
# (a degenerate alignment), timestamps that do not associate. They become warnings recorded beside the results.
EVALUATION_PROBLEMS = (ToolkitError, np.linalg.LinAlgError)


def note_problem(problems: list[str], what: str, exc: BaseException) -> None:
    """Record an evaluation problem (`what` failed because of `exc`) and warn about it."""
    msg = f"{what}: {exc}"
    problems.append(msg)
    warnings.warn(SkippedInputWarning(f"evaluation skipped: {msg}"), stacklevel=3)


def evaluate_run(out_dir: str | Path, gt_file: str | Path | None = None, alignment: Alignment | str = Alignment.SE3,
                 delta: float = 1.0, delta_unit: DeltaUnit | str = DeltaUnit.FRAMES, max_diff: float = 0.01,
                 overlap_threshold: float = 0.33, make_plots: bool = True) -> dict:
    """Metrics of every trajectory in `out_dir` (+ loops when loops.csv and a downward camera are known).
    Writes eval.json and plots/; returns the report dict."""
    out = Path(out_dir)
    if not out.is_dir():
        raise FileNotFoundError(f"{out}: run directory not found")
    run_info = json.loads((out / "run.json").read_text()) if (out / "run.json").is_file() else {}
    seq = None
    if gt_file is None:
        src = run_info.get("sequence")
        if src is None:
            raise VslamError(f"{out}: no ground truth given (--gt FILE) and no run.json naming the sequence")
        seq = open_sequence(src, check_images="none")
        if seq.groundtruth is None:
            raise VslamError(f"{src}: the sequence has no ground truth; give one with --gt FILE")
        t_gt, gt = seq.groundtruth.timestamps, seq.groundtruth.poses
    else:
        t_gt, gt = read_tum(gt_file)
    gt_m = tum_to_se3_matrices(gt)
    report: dict = {"alignment": Alignment(alignment).value, "rpe_delta": delta, "rpe_delta_unit": DeltaUnit(delta_unit).value,
                    "trajectories": {}}
    series, planar = {}, {}
    problems: list[str] = []
    found = 0
    for name, fname in TRAJECTORIES.items():
        f = out / fname
        if not f.is_file():
            continue
        found += 1
        t_est, est = read_tum(f)
        try:
            rep = evaluate(t_gt, gt_m, t_est, tum_to_se3_matrices(est), alignment, max_diff, delta, delta_unit)
            d = rep.to_dict()
            ig, ie = associate(t_gt, t_est, max_diff)
            d["start_to_end"] = start_to_end_error(tum_to_se2(est[ie]), tum_to_se2(gt[ig]))
            aligned, _ = align(gt_m[ig], tum_to_se3_matrices(est[ie]), alignment)
        except EVALUATION_PROBLEMS as exc:
            note_problem(problems, f"{fname}", exc)
            continue
        report["trajectories"][name] = d
        series[name] = (rep.timestamps - t_gt[0], rep.ape_errors)
        planar[name] = np.column_stack([aligned[:, 0, 3], aligned[:, 1, 3]])
    if not found:
        raise FileNotFoundError(f"{out}: no trajectory_vo.txt or trajectory_slam.txt to evaluate")
    loops = None
    if (out / "loops.csv").is_file():
        loops = read_loops_csv(out / "loops.csv")
        camera = seq.camera if seq is not None else None
        if camera is None and "camera" in run_info:
            camera = CameraModel.from_dict(run_info["camera"])
        frame_t = np.asarray(run_info.get("frame_timestamps", [])) if run_info.get("frame_timestamps") else (
            seq.timestamps if seq is not None else None)
        if camera is not None and camera.camera_height is not None and frame_t is not None and len(frame_t):
            gt_frames = Trajectory(t_gt, gt).planar_at(frame_t, max_gap=0.5)
            queried = run_info.get("keyframes")
            kw = dict(queried=np.asarray(queried) if queried else None, r=overlap_threshold,
                      min_separation=int(run_info.get("loop_min_separation", 1)), stamps=frame_t,
                      min_seconds=float(run_info.get("loop_exclude_seconds", 0.0)),
                      after_leaving=bool(run_info.get("loop_exclude_unleft", False)))
            try:
                report["loops"] = {"accepted": loop_precision_recall(camera, gt_frames, loops, **kw),
                                   "kept_by_back_end": loop_precision_recall(camera, gt_frames, loops,
                                                                             use_inliers=True, **kw)}
            except EVALUATION_PROBLEMS as exc:
                note_problem(problems, "loops.csv", exc)
    if problems:
        report["problems"] = problems
    if make_plots:
        pdir = out / "plots"
        pdir.mkdir(exist_ok=True)
        gt_xy = gt[:, :2]
        segs = None
        if loops is not None and "SLAM" in planar:
            segs = _loop_segments(out, loops)
        plots.plot_trajectories(pdir / "trajectories.png", {"ground truth": gt_xy, **planar}, loop_positions=segs,
                                title=f"aligned ({Alignment(alignment).value})")
        if series:
            plots.plot_errors(pdir / "error_over_time.png", series)
        if loops is not None and len(loops):
            _loop_matrix(pdir / "loop_scores.png", loops, run_info.get("keyframes"))
    atomic_write_text(out / "eval.json", json.dumps(report, indent=2, default=float) + "\n")
    return report


def evaluate_result(result, seq) -> dict:
    """metrics.json's "evaluation" of a pipeline result against its sequence's ground truth: per trajectory ("vo",
    "slam") ATE/RPE after an SE(2) alignment and the start-to-end error; "loops": precision/recall of the accepted
    loops and of those the back end kept (floor-footprint overlap ground truth). What cannot be evaluated (one or
    two frames, ground truth that barely moves) is left out with a warning and named in "problems"."""
    gt = seq.groundtruth
    gtm = tum_to_se3_matrices(gt.poses)
    out: dict = {}
    problems: list[str] = []
    gt_frames = seq.groundtruth_planar()[: len(result.timestamps)]
    for name, p in (("vo", result.poses_vo), ("slam", result.poses_slam)):
        try:
            rep = evaluate(gt.timestamps, gtm, result.timestamps, tum_to_se3_matrices(se2_to_tum(p)), "se2")
            d = rep.to_dict()
            ok = ~np.isnan(gt_frames[:, 0])
            d["start_to_end"] = start_to_end_error(p[ok], gt_frames[ok])
        except EVALUATION_PROBLEMS as exc:
            note_problem(problems, f"{name} trajectory", exc)
            continue
        out[name] = d
    if problems:
        out["problems"] = problems
    if result.loops and not problems:
        L = result.loops
        table = LoopTable(np.array([l.query_frame for l in L]), np.array([l.match_frame for l in L]),
                          np.array([l.global_score for l in L]), np.array([l.local_score for l in L]),
                          np.array([l.probability for l in L]), np.array([l.accepted for l in L]),
                          np.array([bool(l.inlier) for l in L]))
        # positives under the detector's own exclusions, as `vslam eval` counts them from run.json: the same run
        # must not report two recalls
        db = result.config.database_params(result.camera)
        kw = dict(queried=result.keyframes, min_separation=db.exclude_recent + 1, stamps=result.timestamps,
                  min_seconds=float(db.exclude_seconds), after_leaving=bool(db.exclude_unleft))
        out["loops"] = {"accepted": loop_precision_recall(result.camera, gt_frames, table, **kw),
                        "kept_by_back_end": loop_precision_recall(result.camera, gt_frames, table, use_inliers=True, **kw)}
    return out


def _loop_matrix(path: Path, loops, keyframes) -> None:
    """loops.csv's candidates on the query x match keyframe grid, coloured by local score (the run's full
    similarity matrix is only in the plot `vslam run` writes)."""
    frames = np.union1d(np.asarray(keyframes if keyframes else [], int),
                        np.union1d(loops.query.astype(int), loops.match.astype(int)))
    judged = loops.inlier is not None
    inl = loops.inlier if judged else [None] * len(loops)
    matrix = similarity_matrix(frames, [(q, [m], [s]) for q, m, s in zip(loops.query, loops.match, loops.local_score)])
    marks = [(q, m, loop_status(bool(a), i, judged)) for q, m, a, i in zip(loops.query, loops.match, loops.accepted,
                                                                            inl)]
    plot_loop_matrix(path, frames, matrix, marks, score_label="local score of the verified candidates",
                     title="loop candidates: local score on the query x match keyframe grid")


def _loop_segments(out: Path, loops) -> dict:
    """Loop edges drawn on the (unaligned) SLAM trajectory, by frame index."""
    t, est = read_tum(out / "trajectory_slam.txt")
    p = est[:, :2]
    segs = {"accepted": [], "outlier": []}   # candidates below threshold would only clutter the map
    for q, m, acc, inl in zip(loops.query, loops.match, loops.accepted,
                              loops.inlier if loops.inlier is not None else [True] * len(loops)):
        if q >= len(p) or m >= len(p) or not acc:
            continue
        segs["accepted" if inl else "outlier"].append((p[q], p[m]))
    return segs


def format_report(rep: dict) -> str:
    lines = [f"alignment {rep['alignment']}, RPE delta {rep['rpe_delta']:g} {rep['rpe_delta_unit']}",
             "| trajectory | matched | path (m) | ATE RMSE (m) | ATE % of path | RPE RMSE (m) | RPE rot (deg) | "
             "start-to-end error (m) |", "|---|---|---|---|---|---|---|---|"]
    for name, d in rep["trajectories"].items():
        se = d["start_to_end"]
        lines.append(f"| {name} | {d['matched']} | {d['path_length_m']:.2f} | {d['ape_m']['rmse']:.4f} | "
                     f"{d['ape_rmse_percent_of_path']:.3f} | {d['rpe_m']['rmse']:.5f} | {d['rpe_rot_deg']['rmse']:.4f} | "
                     f"{se.get('error_distance', float('nan')):.4f} |")
    lines += [f"not evaluated: {p}" for p in rep.get("problems", [])]
    if "loops" in rep:
        for k, v in rep["loops"].items():
            rec = v.get("recall", float("nan"))
            lines.append(f"loops ({k}): {v['reported']} reported, precision {v['precision']:.3f}, recall {rec:.3f}")
    return "\n".join(lines)
