"""`vslam bench pipeline`: end-to-end SLAM throughput, accuracy and memory on simulated sequences.

In one run: a decode-only pass and a VO-only pipeline (baselines), then the full pipeline (mode 4, recording
on) repeated; SLAM and VO accuracy against ground truth; peak memory of a long run measured in a child
process (and of the short run, for the ratio).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

NAME = "pipeline"
HELP = "end-to-end SLAM frames/s, accuracy (ATE, start-to-end) and peak memory on simulated sequences"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/bench_pipeline", help="output folder (JSON, plots, cached sequences)")
    p.add_argument("--frames", type=int, default=2000, help="frames of the speed/accuracy sequence (default 2000)")
    p.add_argument("--length", type=float, default=100.0, help="metres of its closed loop (default 100)")
    p.add_argument("--floor", default="carpet")
    p.add_argument("--mode", type=int, default=4)
    p.add_argument("--runs", type=int, default=3, help="repetitions of the full pipeline (median reported)")
    p.add_argument("--memory-frames", type=int, default=10000, help="frames of the memory run (0 to skip)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="300 frames, 1 run, memory run of 1000 frames")
    p.add_argument("--_child", help=argparse.SUPPRESS)


def _sequence(cache: Path, frames: int, length: float, floor: str, seed: int) -> Path:
    from vslam.sim import SimConfig, simulate

    fps = 20.0
    speed = length / (frames / fps - 4.0)      # the run takes about `frames` frames, with ramps and pauses
    cfg = SimConfig(floor=floor, length=length, speed=speed, fps=fps, seed=seed, max_frames=frames)
    key = hashlib.sha1(json.dumps(cfg.to_dict(), sort_keys=True).encode()).hexdigest()[:10]
    path = cache / f"{floor}-{frames}f-{length:g}m-{key}"
    if not (path / "frames.csv").is_file():
        print(f"simulating {frames} frames ({length:g} m loop over {floor}) into {path} ...", flush=True)
        res = simulate(cfg, path, overwrite=True)
        print(f"  {res.frames} frames in {res.seconds:.0f} s ({res.fps:.0f} frames/s)", flush=True)
    return path


def _decode_only(seq) -> float:
    t0 = time.perf_counter()
    for i in range(len(seq)):
        seq.image(i, gray=True)
    return len(seq) / (time.perf_counter() - t0)


def _run(seq, cfg, out: Path | None, record: bool):
    from vslam.pipeline import Pipeline
    from vslam.recording import RunRecorder

    rec = RunRecorder(out / "recording.rrd", seq.camera) if record else None
    res = Pipeline(cfg, recorder=rec).run(seq)
    if rec is not None:
        rec.close()
    return res


def _accuracy(res, seq) -> dict:
    from vslam.pipeline.outputs import _evaluate

    ev = _evaluate(res, seq)
    out = {}
    for k in ("vo", "slam"):
        d = ev[k]
        out[k] = {"ate_rmse_m": d["ape_m"]["rmse"], "ate_percent_of_path": d["ape_rmse_percent_of_path"],
                  "start_to_end_error_m": d["start_to_end"]["error_distance"],
                  "start_to_end_error_deg": float(np.degrees(abs(d["start_to_end"]["error_dtheta"]))),
                  "path_m": d["path_length_m"]}
    if "loops" in ev:
        out["loops"] = ev["loops"]["kept_by_back_end"]
    return out


def _child(args) -> int:
    """Run the full pipeline on one sequence and print its peak RSS (the parent reads it)."""
    import resource

    from vslam.io import open_sequence
    from vslam.pipeline import PipelineConfig

    seq = open_sequence(args._child)
    cfg = replace(PipelineConfig(), loops=replace(PipelineConfig().loops, mode=args.mode))
    out = Path(args.out) / "memory_run"
    out.mkdir(parents=True, exist_ok=True)
    res = _run(seq, cfg, out, record=True)
    res.write(out, sequence=seq, plots=False)
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(json.dumps({"frames": len(seq), "peak_rss_mb": peak_kb / 1024, "seconds": res.wall_seconds}))
    return 0


def _peak_memory(seq_path: Path, args) -> dict:
    cmd = [sys.executable, "-m", "vslam", "bench", "pipeline", "--_child", str(seq_path), "--out", args.out,
           "--mode", str(args.mode)]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"memory run failed: {p.stderr[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def run(args: argparse.Namespace) -> int:
    if args._child:
        return _child(args)
    from vslam.bench._common import format_table, median, write_json
    from vslam.io import open_sequence
    from vslam.pipeline import PipelineConfig

    if args.quick:
        args.frames, args.length, args.runs, args.memory_frames = 300, 15.0, 1, 1000
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = out / "sequences"
    seq_path = _sequence(cache, args.frames, args.length, args.floor, args.seed)
    seq = open_sequence(seq_path)
    base = PipelineConfig()
    full = replace(base, loops=replace(base.loops, mode=args.mode))
    no_rec = replace(full, recording=replace(full.recording, enabled=False))
    vo_only = replace(no_rec, loops=replace(no_rec.loops, enabled=False))

    decode_fps = _decode_only(seq)
    t0 = time.perf_counter()
    vo_res = _run(seq, vo_only, None, record=False)
    vo_fps = len(seq) / (time.perf_counter() - t0)
    full_fps, last = [], None
    for k in range(args.runs):
        rdir = out / f"run{k}"
        rdir.mkdir(exist_ok=True)
        t0 = time.perf_counter()
        last = _run(seq, full, rdir, record=True)
        full_fps.append(len(seq) / (time.perf_counter() - t0))
    last.write(out / "run0", sequence=seq)
    acc = _accuracy(last, seq)
    acc_vo_only = _accuracy(vo_res, seq)["vo"]
    comp = {k: float(np.mean(v)) * 1000 for k, v in last.timings.items() if k != "final_optimisation"}
    comp["final_optimisation"] = float(last.timings["final_optimisation"][0]) * 1000

    mem = {}
    if args.memory_frames > 0:
        mem_short = _peak_memory(seq_path, args)
        long_len = args.length * args.memory_frames / args.frames
        long_path = _sequence(cache, args.memory_frames, long_len, args.floor, args.seed + 1)
        mem_long = _peak_memory(long_path, args)
        mem = {"short": mem_short, "long": mem_long, "ratio_long_over_short": mem_long["peak_rss_mb"] / mem_short["peak_rss_mb"]}

    rows = [["decode only (baseline)", f"{decode_fps:.0f}", "-", "-", "-"],
            ["VO only, no recording (baseline)", f"{vo_fps:.1f}", f"{acc_vo_only['ate_percent_of_path']:.3f}",
             f"{acc_vo_only['start_to_end_error_m'] * 100:.2f}", "-"],
            [f"full SLAM, mode {args.mode}, recording on (median of {args.runs})", f"{median(full_fps):.1f}",
             f"{acc['slam']['ate_percent_of_path']:.3f}", f"{acc['slam']['start_to_end_error_m'] * 100:.2f}",
             f"{acc.get('loops', {}).get('precision', float('nan')):.3f} / {acc.get('loops', {}).get('recall', float('nan')):.3f}"]]
    print(f"\nsequence: {len(seq)} frames 640x480, {acc['slam']['path_m']:.1f} m closed loop over {args.floor}")
    print(format_table(["configuration", "frames/s", "ATE % of path", "start-to-end error (cm)",
                        "loop precision / recall"], rows))
    print(f"\nfull pipeline / VO only speed: {median(full_fps) / vo_fps:.2f}; VO-only ATE "
          f"{acc_vo_only['ate_rmse_m']:.3f} m vs SLAM {acc['slam']['ate_rmse_m']:.3f} m")
    print("mean ms per frame: " + ", ".join(f"{k} {v:.2f}" for k, v in comp.items()))
    if mem:
        print(f"peak memory: {mem['short']['peak_rss_mb']:.0f} MB at {mem['short']['frames']} frames, "
              f"{mem['long']['peak_rss_mb']:.0f} MB at {mem['long']['frames']} frames "
              f"(ratio {mem['ratio_long_over_short']:.2f})")
    write_json(out / "pipeline.json", {"frames": len(seq), "decode_fps": decode_fps, "vo_only_fps": vo_fps,
                                       "full_fps_runs": full_fps, "full_fps_median": median(full_fps),
                                       "accuracy": acc, "vo_only_accuracy": acc_vo_only, "mean_ms": comp,
                                       "memory": mem, "mode": args.mode, "floor": args.floor})
    print(f"wrote {out / 'pipeline.json'}")
    return 0
