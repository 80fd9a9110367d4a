"""`vslam bench paper`: seed 001's closing experiment end to end, per compression mode, beside the paper's figures.

The paper: a robot drives about 110 m through an office over a printed-wood floor (the false-loop worst case),
taking 7154 images, loops and returns to its start. Table IV gives, per mode, the start-to-end pose difference of
visual odometry and of VSLAM; Table V the storage of all 7154 descriptors and the time to match the last image
against all previous ones, against SIFT.

Here, with each renderer (our simulator, `--floor printed-wood`; the independent ../shared/tools/render_floor.py
with its `--printed` mosaic of a wood-plank photograph): the same path length and frame count, a closed path of two
laps returning to the start, the pipeline once per mode 1-6 (our VO does not depend on the loop descriptor, so mode
1 has VO too, unlike the paper), and a naive ORB + cv2.estimateAffinePartial2D chain as the VO baseline. Assumed
camera (the seed gives none): our default downward camera, 640x480, f = 500 px, 0.5 m above the floor.
"""
from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import time
from concurrent.futures import as_completed
from pathlib import Path

from loops.cdvs import MODES
from vslam.bench.paper_figure import paper_figure
from vslam.bench.paper_pool import TaskPool
from vslam.bench.paper_runs import (
    baseline_chain,
    cdvs_storage_and_time,
    run_mode,
    sift_storage_and_time,
    summary,
    table_v_frames,
    vo_pass,
)
from vslam.bench.paper_tables import PAPER_TABLE_IV, PAPER_TABLE_V, table_iv, table_v
from vslam.bench.results import BenchResult, write_json
from vslam.io import open_sequence
from vslam.paths import shared_data_dir
from vslam.sim import SimConfig, simulate

PAPER_FRAMES = 7154
PAPER_LENGTH_M = 110.0
FPS = 20.0                                  # Hz; 7154 frames over 110 m: 15 mm between frames at 0.31 m/s
INDEPENDENT_TEXTURE = "aws_robomaker_mit0/house_FloorB_01_wood_planks.png"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/bench_paper", help="output folder (JSON, PNG, cached sequences, runs)")
    p.add_argument("--frames", type=int, default=PAPER_FRAMES, help="frames of each sequence (paper: 7154)")
    p.add_argument("--length", type=float, default=PAPER_LENGTH_M, help="path length in metres (paper: about 110)")
    p.add_argument("--renderers", nargs="+", default=["ours", "independent"], choices=["ours", "independent"])
    p.add_argument("--modes", nargs="+", type=int, default=list(MODES), choices=list(MODES))
    p.add_argument("--table-v-frames", type=int, default=0,
                   help="frames encoded for Table V (storage, linear matching time, SIFT); 0 = every frame. Fewer "
                        "frames: storage and time are scaled to --frames, and the table says so")
    p.add_argument("--sift-frames", type=int, default=None,
                   help="frames SIFT describes for Table V (default: --table-v-frames); scaled the same way")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2,
                   help="worker processes (default 2: this machine's cores); the measured units are independent, "
                        "so their figures do not depend on it, only the wall time does")
    p.add_argument("--sequences", default=None,
                   help="folder of the rendered sequences, reused when present (default: OUT/sequences); "
                        "both renderers are deterministic for a given --frames, --length and --seed")
    p.add_argument("--vo-cache", default=None,
                   help="folder keeping each sequence's VO pass between runs, keyed by the VO code, its config and the "
                        "sequence (a pass is reused only under the same key and after a check on its first frames)")
    p.add_argument("--figure-dir", default=None, help="where the PNGs go (default: OUT; docs/img for the docs)")
    p.add_argument("--quick", action="store_true", help="700 frames over 11 m, modes 2 and 4, 200 Table V frames")


# ---------------------------------------------------------------------------------------------------- sequences
def _our_sequence(cache: Path, frames: int, length: float, seed: int) -> Path:
    speed = length / (frames / FPS - 3.0)
    cfg = SimConfig(floor="printed-wood", length=length / 2, laps=2, speed=speed, fps=FPS, seed=seed,
                    max_frames=frames)
    path = cache / f"ours-printed-wood-{frames}f-{length:g}m-s{seed}"
    if not (path / "frames.csv").is_file():
        print(f"simulating {frames} frames over {length:g} m of printed wood into {path} ...", flush=True)
        simulate(cfg, path, overwrite=True)
    return path


def _independent_sequence(cache: Path, frames: int, length: float, seed: int) -> Path:
    tool = shared_data_dir(required=True).parent / "tools" / "render_floor.py"
    texture = shared_data_dir(required=True) / "textures" / INDEPENDENT_TEXTURE
    path = cache / f"independent-printed-{frames}f-{length:g}m-s{seed}"
    if (path / "frames.csv").is_file():
        return path
    size = _loop_size(tool, length, laps=2)
    speed = 0.31
    fps = frames * speed / length
    print(f"rendering {frames} frames over {length:g} m (render_floor.py, printed) into {path} ...", flush=True)
    cmd = [sys.executable, str(tool), str(path), "--textures", str(texture), "--printed", "--shape", "loop",
           "--laps", "2", "--size", f"{size[0]:.3f}", f"{size[1]:.3f}", "--speed", str(speed), "--fps", f"{fps:.4f}",
           "--seed", str(seed)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"render_floor.py failed ({done.returncode}): {done.stderr[-2000:]}")
    return path


def _loop_size(tool: Path, length: float, laps: int) -> tuple[float, float]:
    """Width and height (3:2) of render_floor.py's loop whose `laps` laps measure `length` metres."""
    spec = importlib.util.spec_from_file_location("render_floor", tool)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    *_, one = mod.trajectory("loop", (3.0, 2.0), laps, 1.0, 10.0)
    k = length / one
    return 3.0 * k, 2.0 * k


# ---------------------------------------------------------------------------------------------------- run
def run(args: argparse.Namespace) -> BenchResult:
    """VO once per renderer, then every mode on it, the ORB chain and Table V, as independent tasks on --jobs
    processes: the modes first (Table IV is what the benchmark is for), then SIFT, the chain and Table V."""
    if args.quick:
        args.frames, args.length, args.modes, args.table_v_frames = 700, 11.0, [2, 4], 200
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(args.sequences) if args.sequences else out / "sequences"
    figures = Path(args.figure_dir) if args.figure_dir else out
    figures.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    seqs = {r: (_our_sequence if r == "ours" else _independent_sequence)(cache, args.frames, args.length, args.seed)
            for r in args.renderers}
    n = {r: len(open_sequence(p)) for r, p in seqs.items()}
    cdvs_frames = {r: table_v_frames(n[r], args.table_v_frames) for r in seqs}
    sift_n = args.table_v_frames if args.sift_frames is None else args.sift_frames
    sift_frames = {r: table_v_frames(n[r], sift_n) for r in seqs}
    with TaskPool(args.jobs, t0) as pool:
        pending = {pool.submit(f"{r} VO", vo_pass, p, args.vo_cache, describe=summary): r for r, p in seqs.items()}
        vo, modes = {}, {}
        for f in as_completed(pending):     # a renderer's modes start as soon as its VO is done, the longest first
            r = pending[f]
            vo[r] = f.result()
            for m in sorted(args.modes, reverse=True):
                modes[r, m] = pool.submit(f"{r} mode {m}", run_mode, seqs[r], m, vo[r], out / r / f"mode{m}",
                                          describe=summary)
        sift = {r: pool.submit(f"{r} SIFT", sift_storage_and_time, p, sift_frames[r], n[r] / len(sift_frames[r]),
                               describe=summary) for r, p in seqs.items()}
        chain = {r: pool.submit(f"{r} ORB chain", baseline_chain, p, describe=summary) for r, p in seqs.items()}
        cdvs = {(r, m): pool.submit(f"{r} Table V mode {m}", cdvs_storage_and_time, p, cdvs_frames[r], m,
                                    n[r] / len(cdvs_frames[r]), describe=summary)
                for r, p in seqs.items() for m in args.modes}
        results = {r: {"sequence": str(seqs[r]), "frames": n[r], "table_v_frames": int(len(cdvs_frames[r])),
                       "sift_frames": int(len(sift_frames[r])), "vo_seconds": vo[r].seconds,
                       "vo_reused": vo[r].reused,
                       "runs": [modes[r, m].result() for m in args.modes], "chain": chain[r].result(),
                       "storage": {m: cdvs[r, m].result() for m in args.modes}, "sift": sift[r].result()}
                   for r in seqs}
        tasks = pool.report()
    for r, res in results.items():
        gt = open_sequence(seqs[r]).groundtruth_planar()
        paper_figure(figures / f"paper_{r}.png", r, gt, res["runs"], res["chain"]["poses"])
    minutes = (time.perf_counter() - t0) / 60
    text = _markdown(args, results, minutes)
    print("\n" + text)
    write_json(out / "paper.json", {
        "args": {k: v for k, v in vars(args).items() if isinstance(v, (int, float, str, list))},
        "minutes": minutes, "tasks": tasks, "paper": {"table_iv": PAPER_TABLE_IV, "table_v": PAPER_TABLE_V},
        "results": {r: {**{k: v[k] for k in ("frames", "table_v_frames", "sift_frames", "vo_seconds", "vo_reused",
                                              "storage", "sift")},
                        "chain": {"start_to_end": v["chain"]["start_to_end"], "ate_m": v["chain"]["ate_m"]},
                        "modes": [{k: getattr(m, k) for k in ("mode", "vo", "slam", "vo_ate_m", "slam_ate_m",
                                                             "accepted", "kept", "false_kept", "kept_below_r", "fps",
                                                             "seconds")}
                                  for m in v["runs"]]}
                    for r, v in results.items()}})
    print(f"wrote {out / 'paper.json'} and {', '.join(str(figures / f'paper_{r}.png') for r in results)}")
    return BenchResult(text)


def _markdown(args, results: dict, minutes: float) -> str:
    sections = []
    for r, res in results.items():
        scaled = res["table_v_frames"] < res["frames"] or res["sift_frames"] < res["frames"]
        head = (f"**{r} renderer**: {res['frames']} frames, {args.length:g} m of printed wood (two laps back to "
                f"the start); VO once in {res['vo_seconds']:.0f} s"
                + (" (an earlier run's, from --vo-cache)" if res["vo_reused"] else "")
                + f", shared by every mode; Table V on "
                f"{res['table_v_frames']} frames (SIFT on {res['sift_frames']})"
                + (", scaled to all frames" if scaled else ""))
        sections += [head, table_iv(res["runs"], res["chain"]), table_v(res["storage"], res["sift"])]
    return "\n\n".join(sections) + (f"\n\nWhole benchmark: {minutes:.1f} min on this machine ({args.jobs} worker "
                                     "processes; frames/s = frames / (shared VO seconds + the mode's seconds after "
                                     "VO), measured beside the other worker).")
