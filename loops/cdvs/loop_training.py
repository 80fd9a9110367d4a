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
from loops.cdvs.match import match
from loops.cdvs.model import LoopModel, fit_curve
from loops.cdvs.params import MODES, CdvsParams
from loops.cdvs.trained import TrainedParams, load_trained
from odometry.shared.atomic_io import atomic_path
from odometry.shared.camera import CameraModel
from odometry.shared.footprint import overlap_matrix


@dataclass
class PairScores:
    """Scores of matched keyframe pairs of one sequence, per mode."""

    pairs: np.ndarray                          # (P, 2) keyframe indices (query, earlier)
    overlap: np.ndarray                        # (P,) J from the poses given
    local: dict[int, np.ndarray] = field(default_factory=dict)
    global_: dict[int, np.ndarray] = field(default_factory=dict)
    est_overlap: dict[int, np.ndarray] = field(default_factory=dict)   # MatchResult.overlap per mode
    usable: np.ndarray | None = None           # (P,) pairs whose label the poses can be trusted for

    def save(self, path) -> None:
        arrays = {"pairs": self.pairs, "overlap": self.overlap}
        arrays.update({f"local_{m}": v for m, v in self.local.items()})
        arrays.update({f"global_{m}": v for m, v in self.global_.items()})
        arrays.update({f"estoverlap_{m}": v for m, v in self.est_overlap.items()})
        if self.usable is not None:
            arrays["usable"] = self.usable
        with atomic_path(path, suffix=".npz") as tmp:
            np.savez_compressed(tmp, **arrays)

    @classmethod
    def load(cls, path) -> "PairScores":
        with np.load(path) as z:
            out = cls(z["pairs"], z["overlap"], usable=z["usable"] if "usable" in z.files else None)
            for k in z.files:
                if k.startswith("local_"):
                    out.local[int(k[6:])] = z[k]
                elif k.startswith("global_"):
                    out.global_[int(k[7:])] = z[k]
                elif k.startswith("estoverlap_"):
                    out.est_overlap[int(k[11:])] = z[k]
        return out


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


def floor_params(modes=MODES) -> dict[int, CdvsParams]:
    """The downward-camera preset of every mode."""
    return {m: CdvsParams.floor(m) for m in modes}


def score_sequence(descs: dict[int, list], camera: CameraModel, poses: np.ndarray, exclude_recent: int = 5,
                   shortlist: int = 5, n_random: int = 5, seed: int = 0,
                   trained: TrainedParams | None = None, params: dict[int, CdvsParams] | None = None) -> PairScores:
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
        p = (params[m] if params else CdvsParams.for_mode(m)).matching
        res = [match(descs[m][a], descs[m][b], p, trained) for a, b in pairs]
        out.local[m] = np.array([r.local_score for r in res])
        out.global_[m] = np.array([r.global_score for r in res])
        out.est_overlap[m] = np.array([r.overlap for r in res])
    return out


def fit_loop_model(scored: list[PairScores], r: float = 0.33, provenance: dict | None = None,
                   min_overlap: float | None = None) -> LoopModel:
    """P(J >= r | local score) and thresholds per mode from the scored pairs of one or more sequences. With
    `min_overlap`, only pairs whose verified transform implies at least that overlap are used (the database
    rejects the others before the threshold applies)."""
    modes = sorted(scored[0].local)
    model = LoopModel(overlap_threshold=r, provenance=provenance or {}, min_overlap=min_overlap)
    keep = np.concatenate([ps.usable if ps.usable is not None else np.ones(len(ps.pairs), bool) for ps in scored])
    for m in modes:
        s = np.concatenate([ps.local[m] for ps in scored])
        y = np.concatenate([ps.overlap for ps in scored]) >= r
        k = keep.copy()
        if min_overlap is not None:
            k &= np.concatenate([ps.est_overlap[m] for ps in scored]) >= min_overlap
        model.curves[m] = fit_curve(m, s[k], y[k])
    return model


def trustworthy_pairs(pairs: np.ndarray, relative, footprint_radius: float, max_sigma: float = 0.02,
                      n_sigma: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Which pair labels odometry can be trusted for (seed 001 §III-C: odometry is dependable over short range).

    `relative(i, j) -> (motion (3,), covariance (3, 3))` (e.g. FusedTrajectory.relative). A pair is usable when the
    relative position is known to `max_sigma` metres (its J is reliable), or when the images are so far apart
    that even an n-sigma error cannot make the footprints overlap (certainly J = 0). Returns (usable, sigma)."""
    usable = np.zeros(len(pairs), dtype=bool)
    sigma = np.zeros(len(pairs))
    for k, (a, b) in enumerate(pairs):
        d, cov = relative(int(b), int(a))
        sig = float(np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0)))
        sigma[k] = sig
        usable[k] = sig <= max_sigma or np.hypot(d[0], d[1]) - n_sigma * sig > 2.0 * footprint_radius
    return usable, sigma
