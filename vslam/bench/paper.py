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
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from loops.cdvs import MODES, CdvsParams, LoopDatabase, decode, encode, match
from odometry.shared.poses import between, compose
from vslam.bench.baseline_orb_chain import naive_orb_chain, planar_ate
from vslam.bench.paper_tables import PAPER_TABLE_IV, PAPER_TABLE_V, table_iv, table_v
from vslam.bench.results import BenchResult, write_json
from vslam.bench.timing import median
from vslam.evaluation.metrics import start_to_end_error
from vslam.evaluation.run_eval import evaluate_result
from vslam.io import open_sequence
from vslam.paths import shared_data_dir
from vslam.pipeline import Pipeline, PipelineConfig
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
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="700 frames over 11 m, modes 2 and 4, 200 Table V frames")


@dataclass(frozen=True)
class ModeRun:
    mode: int
    vo: dict                # start_to_end_error of VO (est end relative to start, and its error vs ground truth)
    slam: dict
    vo_ate_m: float
    slam_ate_m: float
    accepted: int           # loops accepted by the detector
    kept: int               # loops kept by the back end
    false_kept: int         # kept loops whose footprints do not overlap (ground truth)
    fps: float
    poses_vo: np.ndarray
    poses_slam: np.ndarray


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


# ---------------------------------------------------------------------------------------------------- table IV
def _run_mode(seq, mode: int, out: Path) -> ModeRun:
    base = PipelineConfig()
    cfg = base.replace(loops=base.loops.replace(mode=mode), recording=base.recording.replace(enabled=False))
    t0 = time.perf_counter()
    res = Pipeline(cfg).run(seq)
    fps = len(res.timestamps) / (time.perf_counter() - t0)
    res.write(out, sequence=seq, plots=False)
    ev = evaluate_result(res, seq)
    kept = ev.get("loops", {}).get("kept_by_back_end", {})
    return ModeRun(mode, ev["vo"]["start_to_end"], ev["slam"]["start_to_end"], ev["vo"]["ape_m"]["rmse"],
                   ev["slam"]["ape_m"]["rmse"], int(sum(bool(l.accepted) for l in res.loops)),
                   int(kept.get("reported", 0)), int(kept.get("false_positives", 0)), fps, res.poses_vo, res.poses_slam)


def _baseline_chain(seq) -> dict:
    gt = seq.groundtruth_planar()
    poses, _, _ = naive_orb_chain(seq, seq.require_camera())
    gt = gt[: len(poses)]
    ok = ~np.isnan(gt[:, 0])
    return {"start_to_end": start_to_end_error(poses, gt), "ate_m": planar_ate(poses[ok], gt[ok]), "poses": poses}


# ---------------------------------------------------------------------------------------------------- table V
def _table_v_frames(n_seq: int, n: int) -> np.ndarray:
    return np.arange(n_seq) if n <= 0 or n >= n_seq else np.unique(np.linspace(0, n_seq - 1, n).round().astype(int))


def _cdvs_storage_and_time(seq, frames: np.ndarray, mode: int, scale: float) -> dict:
    """Bytes of every descriptor, the linear match of the last against all previous, and the indexed query."""
    params = CdvsParams.floor(mode)
    blobs = [encode(seq.image(int(i), gray=True), mode, params) for i in frames]
    descs = [decode(b) for b in blobs]
    last, previous = descs[-1], descs[:-1]
    t0 = time.perf_counter()
    for d in previous:
        match(last, d, params.matching)
    linear = time.perf_counter() - t0
    db = LoopDatabase(mode, params)
    for k, d in enumerate(previous):
        db.add(int(frames[k]), d)
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        db.query(last, int(frames[-1]))
        times.append(time.perf_counter() - t0)
    return {"storage_mb": sum(map(len, blobs)) * scale / 1e6, "linear_s": linear * scale,
            "indexed_s": median(times), "indexed_database": len(previous), "mean_bytes": float(np.mean([len(b) for b in blobs]))}


def _sift_storage_and_time(seq, frames: np.ndarray, scale: float) -> dict:
    """OpenCV SIFT on the same frames: 128 float32 + a keypoint (x, y, size, angle) per feature; ratio-test
    matching of the last image against all previous (brute force, as the paper's SIFT baseline)."""
    sift = cv2.SIFT_create()
    descs = []
    for i in frames:
        _, d = sift.detectAndCompute(seq.image(int(i), gray=True), None)
        descs.append(np.zeros((0, 128), np.float32) if d is None else d)
    storage = sum(d.shape[0] * (128 * 4 + 4 * 4) for d in descs)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    last = descs[-1]
    t0 = time.perf_counter()
    for d in descs[:-1]:
        if len(d) >= 2 and len(last) >= 2:
            pairs = bf.knnMatch(last, d, k=2)
            sum(1 for p in pairs if len(p) == 2 and p[0].distance < 0.8 * p[1].distance)
    return {"storage_mb": storage * scale / 1e6, "linear_s": (time.perf_counter() - t0) * scale}


# ---------------------------------------------------------------------------------------------------- figure
def _anchored(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Estimated poses started at the first ground-truth pose (as the paper draws its paths on the blueprint)."""
    return compose(gt[0], between(est[0], est))


def _figure(path: Path, renderer: str, gt: np.ndarray, runs: list[ModeRun], chain: np.ndarray) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 6), constrained_layout=True)
    for ax, title, key in ((axes[0], "visual odometry (Fig. 7)", "vo"), (axes[1], "VSLAM (Fig. 8)", "slam")):
        ax.plot(gt[:, 0], gt[:, 1], color="black", lw=2.5, alpha=0.35, label="ground truth")
        if key == "vo":   # our VO does not depend on the mode: one curve
            for p, kw in ((chain, dict(color="grey", ls="--", label="ORB + affine chain")),
                          (runs[0].poses_vo, dict(label="our VO (every mode)"))):
                p = _anchored(p, gt)
                ax.plot(p[:, 0], p[:, 1], lw=1, **kw)
        else:
            for r in runs:
                p = _anchored(r.poses_slam, gt)
                ax.plot(p[:, 0], p[:, 1], lw=1, label=f"mode {r.mode}")
        ax.set_title(f"{renderer}: {title}")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        ax.legend(fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------- run
def _one_renderer(args, renderer: str, out: Path) -> dict:
    cache = out / "sequences"
    make = _our_sequence if renderer == "ours" else _independent_sequence
    seq_path = make(cache, args.frames, args.length, args.seed)
    seq = open_sequence(seq_path)
    runs = []
    for m in args.modes:
        print(f"[{renderer}] pipeline, mode {m} ...", flush=True)
        runs.append(_run_mode(seq, m, out / renderer / f"mode{m}"))
        r = runs[-1]
        print(f"  SLAM ATE {r.slam_ate_m:.3f} m, loops accepted {r.accepted} kept {r.kept} (false {r.false_kept}), "
              f"{r.fps:.1f} frames/s", flush=True)
    print(f"[{renderer}] ORB + estimateAffinePartial2D chain ...", flush=True)
    chain = _baseline_chain(seq)
    frames = _table_v_frames(len(seq), args.table_v_frames)
    scale = len(seq) / len(frames)
    print(f"[{renderer}] Table V on {len(frames)} frames (scale x{scale:.2f}) ...", flush=True)
    storage = {m: _cdvs_storage_and_time(seq, frames, m, scale) for m in args.modes}
    sift = _sift_storage_and_time(seq, frames, scale)
    gt = seq.groundtruth_planar()
    _figure(out / f"paper_{renderer}.png", renderer, gt, runs, chain["poses"])
    return {"sequence": str(seq_path), "frames": len(seq), "table_v_frames": int(len(frames)), "runs": runs,
            "chain": chain, "storage": storage, "sift": sift}


def run(args: argparse.Namespace) -> BenchResult:
    if args.quick:
        args.frames, args.length, args.modes, args.table_v_frames = 700, 11.0, [2, 4], 200
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = {r: _one_renderer(args, r, out) for r in args.renderers}
    minutes = (time.perf_counter() - t0) / 60
    sections = []
    for r, res in results.items():
        head = (f"**{r} renderer**: {res['frames']} frames, {args.length:g} m of printed wood (two laps back to "
                f"the start); Table V on {res['table_v_frames']} frames"
                + ("" if res["table_v_frames"] == res["frames"] else ", scaled to all frames"))
        sections += [head, table_iv(res["runs"], res["chain"]), table_v(res["storage"], res["sift"])]
    text = "\n\n".join(sections) + f"\n\nWhole benchmark: {minutes:.1f} min on this machine."
    print("\n" + text)
    write_json(out / "paper.json", {
        "args": {k: v for k, v in vars(args).items() if isinstance(v, (int, float, str, list))},
        "minutes": minutes, "paper": {"table_iv": PAPER_TABLE_IV, "table_v": PAPER_TABLE_V},
        "results": {r: {"frames": v["frames"], "table_v_frames": v["table_v_frames"], "storage": v["storage"],
                        "sift": v["sift"], "chain": {"start_to_end": v["chain"]["start_to_end"],
                                                     "ate_m": v["chain"]["ate_m"]},
                        "modes": [{k: getattr(m, k) for k in ("mode", "vo", "slam", "vo_ate_m", "slam_ate_m",
                                                             "accepted", "kept", "false_kept", "fps")}
                                  for m in v["runs"]]}
                    for r, v in results.items()}})
    print(f"wrote {out / 'paper.json'} and {', '.join(str(out / f'paper_{r}.png') for r in results)}")
    return BenchResult(text)

