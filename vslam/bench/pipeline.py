"""`vslam bench pipeline`: end-to-end SLAM throughput, accuracy and memory on simulated sequences.

In one run: a decode-only pass and a VO-only pipeline (baselines), then the full pipeline (mode 4, recording
on) repeated; SLAM and VO accuracy against ground truth; peak memory of a long run measured in a child
process (and of the short run, for the ratio).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import resource
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from vslam.bench.results import BenchResult, write_json
from vslam.bench.timing import median
from vslam.evaluation.run_eval import evaluate_result
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.recording import RunRecorder
from vslam.sim import SimConfig, simulate


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


def _configs(mode: int):
    """(full SLAM with recording, VO only without recording) at descriptor `mode`."""
    base = PipelineConfig()
    full = replace(base, loops=replace(base.loops, mode=mode))
    no_rec = replace(full, recording=replace(full.recording, enabled=False))
    return full, replace(no_rec, loops=replace(no_rec.loops, enabled=False))


def _decode_only(seq) -> float:
    t0 = time.perf_counter()
    for i in range(len(seq)):
        seq.image(i, gray=True)
    return len(seq) / (time.perf_counter() - t0)


def _decode_orb(seq, features: int = 1000) -> float:
    """Frames/s of decoding plus ORB(1000) detection and description: the cost of the cheapest feature front end,
    so the pipeline's speed reads as a ratio that does not depend on the machine."""
    orb = cv2.ORB_create(features)
    t0 = time.perf_counter()
    for i in range(len(seq)):
        orb.detectAndCompute(seq.image(i, gray=True), None)
    return len(seq) / (time.perf_counter() - t0)


def _run(seq, cfg, out: Path | None, record: bool):
    rec = RunRecorder(out / "recording.rrd", seq.camera) if record else None
    res = Pipeline(cfg, recorder=rec).run(seq)
    if rec is not None:
        rec.close()
    return res


def _accuracy(res, seq) -> dict:
    ev = evaluate_result(res, seq)
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
    seq = open_sequence(args._child)
    full, _ = _configs(args.mode)
    out = Path(args.out) / "memory_run"
    out.mkdir(parents=True, exist_ok=True)
    res = _run(seq, full, out, record=True)
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


def _memory(args, seq_path: Path, cache: Path) -> dict:
    """Peak memory of the full pipeline on this sequence and on a --memory-frames one, each in a child process."""
    if args.memory_frames <= 0:
        return {}
    mem_short = _peak_memory(seq_path, args)
    long_len = args.length * args.memory_frames / args.frames
    mem_long = _peak_memory(_sequence(cache, args.memory_frames, long_len, args.floor, args.seed + 1), args)
    return {"short": mem_short, "long": mem_long,
            "ratio_long_over_short": mem_long["peak_rss_mb"] / mem_short["peak_rss_mb"]}


def _speed(seq, out: Path, runs: int, mode: int) -> dict:
    """Frames/s of decoding alone, of VO only and of the full pipeline (`runs` times); the last full result."""
    full, vo_only = _configs(mode)
    decode_fps = _decode_only(seq)
    orb_fps = _decode_orb(seq)
    t0 = time.perf_counter()
    vo_res = _run(seq, vo_only, None, record=False)
    vo_fps = len(seq) / (time.perf_counter() - t0)
    full_fps, last = [], None
    for k in range(runs):
        rdir = out / f"run{k}"
        rdir.mkdir(exist_ok=True)
        t0 = time.perf_counter()
        last = _run(seq, full, rdir, record=True)
        full_fps.append(len(seq) / (time.perf_counter() - t0))
    return {"decode_fps": decode_fps, "decode_orb_fps": orb_fps, "vo_fps": vo_fps, "vo_result": vo_res, "full_fps": full_fps, "last": last}


def _table(args, sp: dict, acc: dict, acc_vo_only: dict) -> str:
    loops = acc.get("loops", {})
    rows = [["decode only (baseline)", f"{sp['decode_fps']:.0f}", "-", "-", "-"],
            ["decode + ORB(1000) detect and describe (baseline)", f"{sp['decode_orb_fps']:.0f}", "-", "-", "-"],
            ["VO only, no recording (baseline)", f"{sp['vo_fps']:.1f}", f"{acc_vo_only['ate_percent_of_path']:.3f}",
             f"{acc_vo_only['start_to_end_error_m'] * 100:.2f}", "-"],
            [f"full SLAM, mode {args.mode}, recording on (median of {args.runs})", f"{median(sp['full_fps']):.1f}",
             f"{acc['slam']['ate_percent_of_path']:.3f}", f"{acc['slam']['start_to_end_error_m'] * 100:.2f}",
             f"{loops.get('precision', float('nan')):.3f} / {loops.get('recall', float('nan')):.3f}"]]
    return format_table(["configuration", "frames/s", "ATE % of path", "start-to-end error (cm)",
                         "loop precision / recall"], rows)


def _notes(sp: dict, acc: dict, acc_vo_only: dict, comp: dict, mem: dict) -> list[str]:
    lines = [f"full pipeline / decode + ORB(1000) speed: {median(sp['full_fps']) / sp['decode_orb_fps']:.2f}; "
             f"VO only / decode + ORB(1000): {sp['vo_fps'] / sp['decode_orb_fps']:.2f}",
             f"full pipeline / VO only speed: {median(sp['full_fps']) / sp['vo_fps']:.2f}; VO-only ATE "
             f"{acc_vo_only['ate_rmse_m']:.3f} m vs SLAM {acc['slam']['ate_rmse_m']:.3f} m",
             f"VO descriptor path: {sp['vo_result'].summary()['vo_orb_extractions']} ORB extractions on "
             f"{sp['vo_result'].summary()['vo_frames_with_orb']} of {len(sp['vo_result'].timestamps)} frames "
             f"(the rest on the LK fast path)",
             "mean ms per frame: " + ", ".join(f"{k} {v:.2f}" for k, v in comp.items())]
    if mem:
        lines.append(f"peak memory: {mem['short']['peak_rss_mb']:.0f} MB at {mem['short']['frames']} frames, "
                     f"{mem['long']['peak_rss_mb']:.0f} MB at {mem['long']['frames']} frames "
                     f"(ratio {mem['ratio_long_over_short']:.2f})")
    return lines


def run(args: argparse.Namespace) -> BenchResult:
    if args._child:
        return BenchResult(exit_code=_child(args))
    if args.quick:
        args.frames, args.length, args.runs, args.memory_frames = 300, 15.0, 1, 1000
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seq_path = _sequence(out / "sequences", args.frames, args.length, args.floor, args.seed)
    seq = open_sequence(seq_path)
    sp = _speed(seq, out, args.runs, args.mode)
    last = sp["last"]
    last.write(out / "run0", sequence=seq)
    acc = _accuracy(last, seq)
    acc_vo_only = _accuracy(sp["vo_result"], seq)["vo"]
    comp = {k: float(np.mean(v)) * 1000 for k, v in last.timings.items() if k != "final_optimisation"}
    comp["final_optimisation"] = float(last.timings["final_optimisation"][0]) * 1000
    mem = _memory(args, seq_path, out / "sequences")

    title = f"sequence: {len(seq)} frames 640x480, {acc['slam']['path_m']:.1f} m closed loop over {args.floor}"
    table = _table(args, sp, acc, acc_vo_only)
    notes = _notes(sp, acc, acc_vo_only, comp, mem)
    print(f"\n{title}")
    print(table)
    print("\n" + "\n".join(notes))
    write_json(out / "pipeline.json", {"frames": len(seq), "decode_fps": sp["decode_fps"], "decode_orb_fps": sp["decode_orb_fps"], "vo_only_fps": sp["vo_fps"],
                                       "full_fps_runs": sp["full_fps"], "full_fps_median": median(sp["full_fps"]),
                                       "accuracy": acc, "vo_only_accuracy": acc_vo_only, "mean_ms": comp,
                                       "memory": mem, "mode": args.mode, "floor": args.floor})
    print(f"wrote {out / 'pipeline.json'}")
    return BenchResult(f"{title}\n\n{table}\n\n" + "\n\n".join(notes))
