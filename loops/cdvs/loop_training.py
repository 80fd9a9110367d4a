"""Estimating the loop model from a sequence (seed 001 §III-C): match keyframes in every mode, label each matched
pair with loop = J >= r where J comes from poses (the wheel/gyro fusion during training), and fit P(loop | score).

Which pairs are matched mirrors what the database verifies at run time: for each query keyframe, the earlier
keyframes its global shortlist proposes, every earlier keyframe whose footprint overlaps it according to the
poses (so the curve sees the true loops), and a few random earlier keyframes (plain negatives).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from loops.cdvs.codec import decode, encode_all_modes
from loops.cdvs.database import LoopDatabase
from loops.cdvs.groundtruth import pair_overlaps
from loops.cdvs.match import match
from loops.cdvs.model import LoopModel, fit_curve
from loops.cdvs.params import MODES, CdvsParams
from loops.cdvs.trained import TrainedParams, load_trained
from odometry.camera import CameraModel
from odometry.footprint import overlap_matrix


@dataclass
class PairScores:
    """Scores of matched keyframe pairs of one sequence, per mode."""

    pairs: np.ndarray                          # (P, 2) keyframe indices (query, earlier)
    overlap: np.ndarray                        # (P,) J from the poses given
    local: dict[int, np.ndarray] = field(default_factory=dict)
    global_: dict[int, np.ndarray] = field(default_factory=dict)


def encode_all(images: Iterable[np.ndarray], modes=MODES, params: dict[int, CdvsParams] | None = None,
               trained: TrainedParams | None = None) -> dict[int, list]:
    """Decoded descriptors per mode of every image (features are extracted once and encoded in each mode)."""
    trained = trained or load_trained()
    out: dict[int, list] = {m: [] for m in modes}
    for im in images:
        for m, b in encode_all_modes(im, tuple(modes), params, trained).items():
            out[m].append(decode(b))
    return out


def select_pairs(n: int, overlap: np.ndarray, global_rank: dict[int, np.ndarray] | None, exclude_recent: int,
                 n_random: int, rng: np.random.Generator) -> np.ndarray:
    """Pairs (q, k), k <= q - exclude_recent: overlapping ones, shortlisted ones and a few random ones."""
    pairs = set()
    for q in range(n):
        last = q - exclude_recent
        if last < 0:
            continue
        near = np.flatnonzero(overlap[q, : last + 1] > 0)
        pairs.update((q, int(k)) for k in near)
        if global_rank is not None:
            pairs.update((q, int(k)) for k in global_rank.get(q, []))
        if n_random:
            pairs.update((q, int(k)) for k in rng.integers(0, last + 1, size=min(n_random, last + 1)))
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


def score_sequence(descs: dict[int, list], camera: CameraModel, poses: np.ndarray, exclude_recent: int = 5,
                   shortlist: int = 5, n_random: int = 5, seed: int = 0,
                   trained: TrainedParams | None = None) -> PairScores:
    """Match the selected keyframe pairs in every mode. `poses` (N, 3) are the keyframes' planar poses."""
    trained = trained or load_trained()
    modes = sorted(descs)
    n = len(descs[modes[0]])
    rng = np.random.default_rng(seed)
    J = overlap_matrix(camera, poses)
    ranks: dict[int, set] = {}
    for m in modes:  # the global shortlist of each mode proposes candidates, as in the database
        db = LoopDatabase(m, trained=trained)
        for q, d in enumerate(descs[m]):
            if q - exclude_recent >= 0:
                g = db.global_scores(d, q - exclude_recent + 1)
                top = np.argsort(-g, kind="stable")[:shortlist]
                ranks.setdefault(q, set()).update(int(t) for t in top)
            db.add(q, d)
    pairs = select_pairs(n, J, {q: sorted(v) for q, v in ranks.items()}, exclude_recent, n_random, rng)
    out = PairScores(pairs, J[pairs[:, 0], pairs[:, 1]] if len(pairs) else np.zeros(0))
    for m in modes:
        p = CdvsParams.for_mode(m).matching
        res = [match(descs[m][a], descs[m][b], p, trained) for a, b in pairs]
        out.local[m] = np.array([r.local_score for r in res])
        out.global_[m] = np.array([r.global_score for r in res])
    return out


def fit_loop_model(scored: list[PairScores], r: float = 0.33, provenance: dict | None = None) -> LoopModel:
    """P(J >= r | local score) and thresholds per mode from the scored pairs of one or more sequences."""
    modes = sorted(scored[0].local)
    model = LoopModel(overlap_threshold=r, provenance=provenance or {})
    for m in modes:
        s = np.concatenate([ps.local[m] for ps in scored])
        y = np.concatenate([ps.overlap for ps in scored]) >= r
        model.curves[m] = fit_curve(m, s, y)
    return model


def precision_recall(scores: np.ndarray, overlap: np.ndarray, threshold: float, r: float = 0.33) -> tuple[float, float, int]:
    """Precision and recall of `score >= threshold` against loop = J >= r; also the number of false loops."""
    acc = scores >= threshold
    pos = overlap >= r
    tp = int(np.sum(acc & pos))
    fp = int(np.sum(acc & ~pos))
    prec = tp / (tp + fp) if tp + fp else 1.0
    rec = tp / int(pos.sum()) if pos.any() else float("nan")
    return prec, rec, fp
