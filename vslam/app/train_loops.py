"""Learn the loop model P(loop | local score) and the per-mode thresholds from odometry-labelled sequences
(`vslam train-loops`).

Each training sequence needs wheel odometry (odometry.csv), optionally a gyro (imu.csv), and a downward camera
(camera_height): relative motion comes from the wheel/gyro fusion (never from ground truth), the floor-footprint
overlap J of keyframe pairs from those poses, and loop = J >= r (seed 001 §III).
"""
from __future__ import annotations

import time
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from loops.cdvs import MODES
from loops.cdvs.loop_training import (
    PairScores,
    encode_all,
    fit_loop_model,
    floor_params,
    score_sequence,
    trustworthy_pairs,
)
from loops.cdvs.model import LoopModel
from loops.cdvs.plots import plot_loop_model
from loops.cdvs.trained import TrainedParams, load_trained
from vslam.app.odometry import fuse_sequence_odometry
from vslam.errors import SkippedInputWarning, VslamError
from vslam.io import open_sequence


@dataclass(frozen=True)
class PairSampling:
    """Which keyframe pairs of a training sequence are matched and labelled."""
    every: int = 1              # every N-th frame is a keyframe
    exclude_recent: int = 5     # no pairs closer than this many keyframes
    shortlist: int = 5          # global candidates per query, as at run time
    random: int = 5             # random earlier keyframes per query (negatives)
    seed: int = 0
    max_sigma: float = 0.02     # use a label only if the fused relative position is known to this (metres)


def _cache_name(path: str | Path, trained: TrainedParams, s: PairSampling, modes: Sequence[int]) -> str:
    """A file name that changes with everything the cached pair scores depend on."""
    full = Path(path).resolve()
    return (f"{full.name}-{zlib.crc32(str(full).encode()):08x}-{trained.params_id:04x}-e{s.every}-x{s.exclude_recent}-"
            f"s{s.shortlist}-r{s.random}-{s.seed}-{''.join(map(str, modes))}-v2.npz")


def score_training_sequence(path: str | Path, modes: Sequence[int], sampling: PairSampling, trained: TrainedParams,
                            cache: str | Path | None = None) -> tuple[PairScores, int]:
    """Matched keyframe pairs of one sequence with their overlap J and trustworthy-label mask (`usable`), and the
    number of keyframes. Pair scores are kept in / reused from `cache` when given."""
    seq = open_sequence(path)
    cam = seq.require_camera()
    if cam.camera_height is None:
        raise VslamError(f"{path}: camera.yaml has no camera_height: J needs a downward-facing camera")
    if seq.odometry is None:
        raise VslamError(f"{seq.root or seq.name}: train-loops needs wheel odometry (odometry.csv)")
    fused = fuse_sequence_odometry(seq)
    idx = np.arange(0, len(seq), sampling.every)
    cached = Path(cache) / _cache_name(path, trained, sampling, modes) if cache else None
    if cached is not None and cached.is_file():
        ps = PairScores.load(cached)
    else:
        params = floor_params(modes)
        descs = encode_all((seq.image(int(i), gray=True) for i in idx), modes, params, trained=trained)
        ps = score_sequence(descs, cam, fused.poses[idx], exclude_recent=sampling.exclude_recent,
                            shortlist=sampling.shortlist, n_random=sampling.random, seed=sampling.seed,
                            trained=trained, params=params)
        if cached is not None:
            ps.save(cached)
    rmax = float(np.max(np.linalg.norm(cam.footprint(), axis=1)))
    ps.usable, _ = trustworthy_pairs(ps.pairs, lambda i, j: fused.relative(int(idx[i]), int(idx[j])), rmax,
                                     sampling.max_sigma)
    return ps, len(idx)


def train_loop_model(sequences: Sequence[str | Path], out: str | Path, modes: Sequence[int] = MODES,
                     overlap: float = 0.33, sampling: PairSampling = PairSampling(),
                     min_overlap: float | None = None, cache: str | Path | None = None, plot: bool = True,
                     command: str = "vslam train-loops", log: Callable[[str], None] | None = None) -> LoopModel:
    """Fit the loop model on the sequences and save it to `out` (and its curves beside it as PNG when `plot`).

    A pair is a loop when its footprint overlap J >= `overlap` and, unless `min_overlap` < 0, the overlap implied by
    the verified transform >= `min_overlap` (default `overlap` + 0.05). `command` is recorded in the provenance;
    `log` gets one line per sequence.
    """
    if not 0 < overlap <= 1:
        raise VslamError(f"--overlap must be in (0, 1], got {overlap}")
    if sampling.every < 1:
        raise VslamError("--every must be >= 1")
    implied = overlap + 0.05 if min_overlap is None else (None if min_overlap < 0 else min_overlap)
    if implied is not None and implied > 1:
        raise VslamError(f"--min-overlap must be <= 1, got {min_overlap}")
    trained = load_trained()
    scored, sources = [], []
    for path in sequences:
        t0 = time.perf_counter()
        ps, keyframes = score_training_sequence(path, modes, sampling, trained, cache)
        scored.append(ps)
        loops = int(np.sum((ps.overlap >= overlap) & ps.usable))
        sources.append({"sequence": str(path), "keyframes": keyframes, "pairs": int(len(ps.pairs)),
                        "loop_pairs": loops, "pairs_used": int(ps.usable.sum())})
        if log is not None:
            log(f"{path}: {keyframes} keyframes, {len(ps.pairs)} pairs matched, {int(ps.usable.sum())} with a "
                f"trustworthy label ({loops} loops), {time.perf_counter() - t0:.0f} s")
    # a model fitted on nothing has every threshold infinite: it would silently disable loop closure
    used, positives = sum(x["pairs_used"] for x in sources), sum(x["loop_pairs"] for x in sources)
    names = ", ".join(str(p) for p in sequences)
    if used == 0:
        raise VslamError(f"{names}: no training pairs (keyframe pairs with a trustworthy odometry label); use longer "
                         "sequences, a smaller --every or --exclude-recent, or a larger --max-sigma")
    if positives == 0:
        raise VslamError(f"{names}: none of the {used} training pairs is a loop (footprint overlap J >= {overlap}); "
                         "the sequences must revisit places")
    provenance = {"command": command, "sequences": sources, "overlap_threshold": overlap,
                  "relative_motion": "odometry.fusion.fuse_wheel_gyro (wheel odometry + gyro)",
                  "every": sampling.every, "exclude_recent": sampling.exclude_recent, "shortlist": sampling.shortlist,
                  "random": sampling.random, "seed": sampling.seed, "descriptor_params_id": trained.params_id,
                  "max_sigma": sampling.max_sigma, "descriptor_preset": "CdvsParams.floor", "min_overlap": implied}
    model = fit_loop_model(scored, overlap, provenance, min_overlap=implied)
    if not any(np.isfinite(model.threshold(m)) for m in model.curves):
        # a fit, but one that accepts no loop: written (it is what the data says), never silently
        warnings.warn(SkippedInputWarning(
            f"{names}: no mode reaches a finite loop threshold on these {used} pairs ({positives} loops): "
            "this model accepts no loop; train on more revisits"), stacklevel=2)
    out = Path(out)
    model.save(out)
    if plot:
        plot_loop_model(model, out.with_suffix(".png"))
    return model
