"""`vslam bench loops`: standalone loop detection (`vslam loops`) across regimes, on both renderers.

Sequences (reporting seed 2 by default; seed 1 was used while developing, i.e. the tuning half):
our simulator (`vslam simulate`) and the independent renderer (../shared/tools/render_floor.py with the shared
textures), a printed (periodic) floor and a natural one, 2 laps each at 10 fps; and a low-rate lawnmower regime
from our simulator (0.2 Hz, about 35 % of the footprint between frames, 180-degree turns between lanes; the
independent renderer has no lawnmower path). Each is run with the default options (odometry: the sequence's wheel
odometry; footprint exclusion and motion gate), with `--appearance-only`, and with the former defaults
(appearance only, 20 most recent keyframes excluded) as the baseline of the same run.

Ground truth is footprint overlap J (seed 001 eq. 3-4, r = 0.33) of the true poses. A query is a positive when an
earlier frame overlaps it by J >= r although the camera had left that frame's footprint in between (a later frame
with J = 0 to it) and at least the time exclusion has passed: a revisit, not the same visit. Precision counts
accepted loops with J >= r; "no overlap" counts accepted loops between footprints that do not overlap at all.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

from odometry.shared.footprint import overlap_matrix, overlap_pairs
from vslam.app.loops import detect_sequence_loops
from vslam.bench.results import BenchResult, write_json
from vslam.evaluation.loops import read_loops_csv
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.paths import shared_data_dir

R = 0.33


def revisit_truth(camera, gt: np.ndarray, stamps: np.ndarray, exclude_seconds: float) -> np.ndarray:
    """(N,) bool: frame q has an earlier frame j with J >= R that the camera had left (some frame between them
    with J(j, k) = 0) and that is at least `exclude_seconds` older."""
    J = overlap_matrix(camera, gt)
    n = len(gt)
    left_at = np.full(n, n)          # first later frame whose footprint does not overlap frame j
    for j in range(n):
        zero = np.flatnonzero(J[j, j + 1:] <= 0.0)
        if len(zero):
            left_at[j] = j + 1 + zero[0]
    pos = np.zeros(n, bool)
    for q in range(n):
        js = np.flatnonzero((J[q, :q] >= R) & (left_at[:q] < q) & (stamps[q] - stamps[:q] >= exclude_seconds))
        pos[q] = len(js) > 0
    return pos


def score(seq_dir: Path, out: Path, exclude_seconds: float) -> dict:
    seq = open_sequence(seq_dir)
    gt = seq.groundtruth_planar()
    loops = read_loops_csv(out / "loops.csv")
    q, m = loops.query[loops.accepted], loops.match[loops.accepted]
    J = overlap_pairs(seq.camera, gt[q], gt[m]) if len(q) else np.zeros(0)
    pos = revisit_truth(seq.camera, gt, np.asarray(seq.timestamps, float), exclude_seconds)
    hit = np.zeros(len(gt), bool)
    hit[q[J >= R]] = True
    n_pos = int(pos.sum())
    return {"frames": len(gt), "accepted": int(len(q)), "true": int((J >= R).sum()),
            "precision": float((J >= R).mean()) if len(q) else float("nan"),
            "no_overlap": int((J <= 0).sum()), "positive_queries": n_pos,
            "recall": float((hit & pos).sum() / n_pos) if n_pos else float("nan")}


def make_sequences(root: Path, seed: int, quick: bool) -> dict[str, Path]:
    """The sequences of the run (rendered once into `root`)."""
    data = shared_data_dir(required=True)
    tex, render_floor = data / "textures", data.parent / "tools" / "render_floor.py"   # the independent renderer
    laps = "1" if quick else "2"
    specs = {
        "sim printed-wood": ["simulate", "--floor", "printed-wood", "--laps", laps, "--fps", "10"],
        "sim carpet": ["simulate", "--floor", "carpet", "--laps", laps, "--fps", "10"],
        "sim lawnmower 0.2 Hz": ["simulate", "--floor", "gravel", "--trajectory", "lawnmower", "--fps", "0.2",
                                 "--speed", "0.045", "--turn-radius", "0.1", "--length", "12"],
        "render_floor printed wood": ["render", "--printed", "--textures",
                                      str(tex / "aws_robomaker_mit0" / "house_FloorB_01_wood_planks.png")],
        "render_floor gravel+concrete": ["render", "--textures", str(tex / "skimage_cc0" / "gravel.png"),
                                         str(tex / "gazebo_models_ccby3" / "cloverleaf_interchange__concrete.png")],
    }
    out = {}
    for name, spec in specs.items():
        d = root / name.replace(" ", "_").replace("+", "_")
        if not (d / "frames.csv").exists():
            if spec[0] == "simulate":
                cmd = [sys.executable, "-m", "vslam", "simulate", str(d), *spec[1:], "--seed", str(seed), "--quiet",
                       "--overwrite"]
            else:
                cmd = [sys.executable, str(render_floor), str(d), *spec[1:], "--laps", laps, "--fps", "10",
                       "--seed", str(seed)]
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        out[name] = d
    return out


VARIANTS = {  # name -> detect_sequence_loops options
    "default (wheel odometry)": {},
    "--appearance-only": {"appearance_only": True},
    "former defaults (appearance only, --exclude-recent 20)": {"appearance_only": True, "exclude_recent": 20,
                                                                "exclude_seconds": 0.0},
}
VO_VARIANT = ("--odometry vo (our VO, no wheel)", {"odometry": "vo"})   # run on the low-rate sequence


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("out/bench_loops"), help="output folder (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=2, help="sequence seed; 1 is the tuning half (default: 2)")
    parser.add_argument("--quick", action="store_true", help="1 lap instead of 2")


def run(args: argparse.Namespace) -> BenchResult:
    seqs = make_sequences(args.out / f"sequences-seed{args.seed}", args.seed, args.quick)
    rows, results = [], {}
    for sname, sdir in seqs.items():
        variants = dict(VARIANTS)
        if "lawnmower" in sname:
            variants[VO_VARIANT[0]] = VO_VARIANT[1]
        for vname, opts in variants.items():
            out = args.out / "runs" / f"{sdir.name}--{list(variants).index(vname)}"
            run_ = detect_sequence_loops(sdir, out, **opts)
            s = score(sdir, out, float(opts.get("exclude_seconds", 2.0)))
            s.update({"odometry": run_.summary["odometry"], "rejected_by_motion": run_.summary["rejected_by_motion"]})
            results[f"{sname} / {vname}"] = s
            rows.append([sname, vname, s["frames"], s["accepted"], s["no_overlap"], s["precision"],
                         s["positive_queries"], s["recall"], s["rejected_by_motion"]])
            print(f"{sname} / {vname}: {s}", flush=True)
    table = format_table(["sequence", "options", "frames", "accepted loops", "accepted, no overlap (J = 0)",
                          "precision (J >= 0.33)", "revisit queries", "recall", "rejected by motion gate"],
                         rows, floatfmt=".3f")
    write_json(args.out / "loops.json", {"benchmark": "loops", "seed": args.seed, "results": results,
                                         "table": table})
    print(table)
    return BenchResult(f"Sequences of seed {args.seed} (seed 1: tuning half).\n\n{table}")
