"""`vslam train-loops SEQ... --out loops-model.json`: learn P(loop | local score) and the per-mode thresholds.

Each training sequence needs wheel odometry (odometry.csv), optionally a gyro (imu.csv), and a downward camera
(camera_height): relative motion comes from the wheel/gyro fusion (never from ground truth), the floor-footprint
overlap J of keyframe pairs from those poses, and loop = J >= r (seed 001 §III).
"""
from __future__ import annotations

import argparse

from vslam.errors import VslamError

NAME = "train-loops"
HELP = "learn the loop model P(loop|score) and per-mode thresholds from odometry-labelled sequences"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequences", nargs="+", help="training sequence directories (with odometry.csv)")
    p.add_argument("--out", required=True, help="model JSON to write (a PNG of the curves is written beside it)")
    p.add_argument("--modes", default="1,2,3,4,5,6", help="comma-separated modes (default all)")
    p.add_argument("--overlap", type=float, default=0.33, help="loop when the footprint overlap J >= this (r)")
    p.add_argument("--every", type=int, default=1, help="use every N-th frame as a keyframe (default 1)")
    p.add_argument("--exclude-recent", type=int, default=5,
                   help="do not pair keyframes closer than this many keyframes (default 5)")
    p.add_argument("--shortlist", type=int, default=5, help="global candidates per query, as at run time")
    p.add_argument("--random", type=int, default=5, help="random earlier keyframes per query (negatives)")
    p.add_argument("--max-sigma", type=float, default=0.02,
                   help="use a pair's label only if the fused relative position is known to this many metres "
                        "(or the images are certainly apart); default 0.02")
    p.add_argument("--min-overlap", type=float, default=None,
                   help="a loop also needs the overlap implied by the verified transform >= this (default: the "
                        "overlap threshold + 0.05; a negative value turns the check off)")
    p.add_argument("--cache", help="directory to keep per-sequence pair scores (re-fits skip the matching)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-plot", action="store_true")
    p.add_argument("--quiet", action="store_true")


def _parse_modes(text: str) -> tuple[int, ...]:
    try:
        modes = tuple(sorted({int(m) for m in text.split(",") if m.strip()}))
    except ValueError:
        raise VslamError(f"--modes: expected comma-separated integers 1-6, got {text!r}") from None
    if not modes or any(m < 1 or m > 6 for m in modes):
        raise VslamError(f"--modes: modes must be in 1..6, got {text!r}")
    return modes


def fused_trajectory(seq):
    """The wheel/gyro fusion (odometry.fusion) at the frame times."""
    from odometry.fusion import fuse_wheel_gyro

    if seq.odometry is None:
        raise VslamError(f"{seq.root or seq.name}: train-loops needs wheel odometry (odometry.csv)")
    imu = seq.imu
    fused = fuse_wheel_gyro(seq.odometry.timestamps, seq.odometry.v, seq.odometry.omega,
                            None if imu is None else imu.timestamps, None if imu is None else imu.gyro_z,
                            seq.timestamps)
    return fused


def run(a: argparse.Namespace) -> int:
    import sys
    import time
    import zlib
    from pathlib import Path

    import numpy as np

    from loops.cdvs.loop_training import (
        PairScores,
        encode_all,
        fit_loop_model,
        floor_params,
        score_sequence,
        trustworthy_pairs,
    )
    from loops.cdvs.plots import plot_loop_model
    from loops.cdvs.trained import load_trained
    from vslam.io import open_sequence

    modes = _parse_modes(a.modes)
    if not 0 < a.overlap <= 1:
        raise VslamError(f"--overlap must be in (0, 1], got {a.overlap}")
    if a.every < 1:
        raise VslamError("--every must be >= 1")
    trained = load_trained()
    scored, sources = [], []
    for path in a.sequences:
        t0 = time.perf_counter()
        seq = open_sequence(path)
        cam = seq.require_camera() if hasattr(seq, "require_camera") else seq.camera
        if cam is None or cam.camera_height is None:
            raise VslamError(f"{path}: camera.yaml has no camera_height: J needs a downward-facing camera")
        fused = fused_trajectory(seq)
        idx = np.arange(0, len(seq), a.every)
        key = f"{Path(path).resolve().name}-{zlib.crc32(str(Path(path).resolve()).encode()):08x}-" \
              f"{trained.params_id:04x}-e{a.every}-x{a.exclude_recent}-" \
              f"s{a.shortlist}-r{a.random}-{a.seed}-{''.join(map(str, modes))}-v2.npz"
        cached = Path(a.cache) / key if a.cache else None
        if cached is not None and cached.is_file():
            ps = PairScores.load(cached)
        else:
            images = (seq.image(int(i), gray=True) for i in idx)
            params = floor_params(modes)
            descs = encode_all(images, modes, params, trained=trained)
            ps = score_sequence(descs, cam, fused.poses[idx], exclude_recent=a.exclude_recent,
                                shortlist=a.shortlist, n_random=a.random, seed=a.seed, trained=trained,
                                params=params)
            if cached is not None:
                ps.save(cached)
        rmax = float(np.max(np.linalg.norm(cam.footprint(), axis=1)))
        ps.usable, _ = trustworthy_pairs(ps.pairs, lambda i, j: fused.relative(int(idx[i]), int(idx[j])), rmax,
                                         a.max_sigma)
        scored.append(ps)
        loop = ps.overlap >= a.overlap
        sources.append({"sequence": str(path), "keyframes": int(len(idx)), "pairs": int(len(ps.pairs)),
                        "loop_pairs": int(np.sum(loop & ps.usable)), "pairs_used": int(ps.usable.sum())})
        if not a.quiet:
            print(f"{path}: {len(idx)} keyframes, {len(ps.pairs)} pairs matched, {int(ps.usable.sum())} with a "
                  f"trustworthy label ({int(np.sum(loop & ps.usable))} loops), {time.perf_counter() - t0:.0f} s",
                  file=sys.stderr)
    provenance = {"command": "vslam train-loops " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["train-loops"]
                  else "vslam train-loops", "sequences": sources, "overlap_threshold": a.overlap,
                  "relative_motion": "odometry.fusion.fuse_wheel_gyro (wheel odometry + gyro)",
                  "every": a.every, "exclude_recent": a.exclude_recent, "shortlist": a.shortlist,
                  "random": a.random, "seed": a.seed, "descriptor_params_id": trained.params_id,
                  "max_sigma": a.max_sigma,
                  "descriptor_preset": "CdvsParams.floor"}
    min_overlap = a.overlap + 0.05 if a.min_overlap is None else (None if a.min_overlap < 0 else a.min_overlap)
    if min_overlap is not None and min_overlap > 1:
        raise VslamError(f"--min-overlap must be <= 1, got {a.min_overlap}")
    provenance["min_overlap"] = min_overlap
    model = fit_loop_model(scored, a.overlap, provenance, min_overlap=min_overlap)
    out = Path(a.out)
    model.save(out)
    if not a.no_plot:
        plot_loop_model(model, out.with_suffix(".png"))
    if not a.quiet:
        for m in modes:
            print(f"mode {m}: threshold {model.threshold(m):.3g}")
        print(f"wrote {out}" + ("" if a.no_plot else f" and {out.with_suffix('.png')}"))
    return 0
