"""`vslam run SEQ --out OUT`: the whole SLAM pipeline on a sequence."""
from __future__ import annotations

import argparse

NAME = "run"
HELP = "run SLAM (VO + compact-descriptor loops + robust pose graph) on a sequence; writes trajectories, loops, " \
       "graph, metrics, plots and a Rerun recording"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", help="sequence directory (or TUM RGB-D / KITTI folder, image folder, video)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--mode", type=int, choices=range(1, 7), metavar="1..6",
                   help="descriptor size mode (512 B .. 16 kB per keyframe; default 4)")
    p.add_argument("--loop-model", help="P(loop|score) model from `vslam train-loops` (default: the shipped model)")
    p.add_argument("--incremental", action="store_true", help="iSAM2 as keyframes arrive instead of batch LM")
    p.add_argument("--config", help="YAML or TOML file with pipeline settings (see --print-config)")
    p.add_argument("--no-loops", action="store_true", help="visual odometry only")
    p.add_argument("--no-recording", action="store_true", help="do not write recording.rrd")
    p.add_argument("--camera", help="camera.yaml for image folders and videos")
    p.add_argument("--max-frames", type=int, help="process only the first N frames")
    p.add_argument("--print-config", action="store_true", help="print the effective configuration as YAML and exit")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")


def build_config(a: argparse.Namespace):
    from dataclasses import replace

    from vslam.pipeline.config import PipelineConfig

    cfg = PipelineConfig.load(a.config) if a.config else PipelineConfig()
    loops = cfg.loops
    if a.mode is not None:
        loops = replace(loops, mode=a.mode)
    if a.loop_model:
        loops = replace(loops, model=a.loop_model)
    if a.no_loops:
        loops = replace(loops, enabled=False)
    cfg = replace(cfg, loops=loops)
    if a.incremental:
        cfg = replace(cfg, incremental=True)
    if a.no_recording:
        cfg = replace(cfg, recording=replace(cfg.recording, enabled=False))
    return cfg


def format_summary(result, metrics_eval: dict | None, out) -> str:
    s = result.summary()
    st = s["vo_status"]
    ms = s["median_ms"]
    lines = [f"vslam run: {s['frames']} frames in {s['wall_seconds']:.1f} s ({s['frames_per_second']:.1f} frames/s), "
             f"{s['keyframes']} keyframes",
             f"  VO       ok {st.get('ok', 0)}, fallback {st.get('fallback', 0)}, lost {st.get('lost', 0)}; "
             f"median {ms.get('vo', 0):.1f} ms/frame",
             f"  loops    {s['loops_verified']} verified candidates, {s['loops_accepted']} accepted, "
             f"{s['loops_kept']} kept by the back end, {s['loops_rejected_by_backend']} rejected as outliers; "
             f"descriptor {s['descriptor_bytes_mean']:.0f} B mean / {s['descriptor_bytes_max']} B max"]
    if metrics_eval:
        for name in ("vo", "slam"):
            d = metrics_eval[name]
            se = d["start_to_end"]
            lines.append(f"  {name.upper():<8} ATE {d['ape_m']['rmse']:.4f} m RMSE ({d['ape_rmse_percent_of_path']:.3f} % of "
                         f"{d['path_length_m']:.1f} m), start-to-end error {se.get('error_distance', float('nan')):.4f} m")
        if "loops" in metrics_eval:
            la = metrics_eval["loops"]["kept_by_back_end"]
            lines.append(f"  loops vs footprint ground truth: precision {la['precision']:.3f}, "
                         f"recall {la.get('recall', float('nan')):.3f}")
    lines.append(f"  outputs  {out}/ (trajectory_vo.txt, trajectory_slam.txt, loops.csv, graph.g2o, metrics.json, "
                 f"plots/{', recording.rrd' if result.config.recording.enabled else ''})")
    return "\n".join(lines)


def run(a: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from vslam.cli.progress import Progress
    from vslam.io import open_sequence
    from vslam.pipeline import Pipeline

    cfg = build_config(a)
    if a.print_config:
        print(cfg.dumps(), end="")
        return 0
    seq = open_sequence(a.sequence, camera=a.camera)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    recorder = None
    if cfg.recording.enabled:
        from vslam.recording import RunRecorder

        recorder = RunRecorder(out / "recording.rrd", seq.camera, recording_id=f"vslam-{seq.name}",
                               jpeg_quality=cfg.recording.jpeg_quality, image_every=cfg.recording.image_every)
    bar = Progress(len(seq) if a.max_frames is None else min(len(seq), a.max_frames), label="vslam run",
                   enabled=None if not a.quiet else False)
    try:
        result = Pipeline(cfg, recorder=recorder).run(seq, progress=bar.update, max_frames=a.max_frames)
    except BaseException:
        if recorder is not None:
            recorder.abort()
        raise
    bar.close()
    if recorder is not None:
        recorder.close()
    result.write(out, sequence=seq)
    if not a.quiet:
        metrics = json.loads((out / "metrics.json").read_text())
        print(format_summary(result, metrics.get("evaluation"), out))
    return 0
