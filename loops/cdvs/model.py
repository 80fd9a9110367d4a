"""The learned loop model: P(loop | local score) per mode and the per-mode acceptance threshold (seed 001 §III-C).

loop(Ia, Ib) = 1 when the floor-footprint overlap J >= r (eq. 3-4). P(J >= r | score = s) is estimated from
labelled pairs by binning the score (eq. 6), made non-decreasing in s by isotonic regression (a higher local score
never makes a loop less likely), and the threshold is the lowest score from which P is certain (= 1), as in
Table III. The model is a small JSON file.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loops.cdvs.params import MODES
from loops.cdvs.trained import DATA_DIR
from loops.errors import LoopsError
from odometry.shared.atomic_io import atomic_write_text

DEFAULT_MODEL = DATA_DIR / "loop_model.json"
FORMAT = "vslam-loop-model"
VERSION = 1
# score bins: 0, then geometric steps of ~10 % from 0.25 to 400
DEFAULT_EDGES = np.concatenate([[0.0], np.geomspace(0.25, 400.0, 78)])


@dataclass(frozen=True)
class ModeCurve:
    mode: int
    edges: np.ndarray        # (B,) lower score edge of each bin; the last bin is open-ended
    probability: np.ndarray  # (B,) P(loop | score in bin), non-decreasing
    positives: np.ndarray    # (B,) loop pairs per bin
    totals: np.ndarray       # (B,) pairs per bin
    threshold: float         # lowest score with P = 1 (inf if never certain)

    def prob(self, score: np.ndarray | float) -> np.ndarray | float:
        i = np.clip(np.searchsorted(self.edges, score, side="right") - 1, 0, len(self.probability) - 1)
        return self.probability[i]


def isotonic(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted pool-adjacent-violators: the non-decreasing fit of y (bins with weight 0 take their neighbours)."""
    vals, wts, lens = [], [], []
    for yi, wi in zip(y.astype(float), w.astype(float)):
        vals.append(yi if wi > 0 else 0.0)
        wts.append(wi)
        lens.append(1)
        while len(vals) > 1 and wts[-1] > 0 and (wts[-2] == 0 or vals[-2] > vals[-1]):
            if wts[-2] == 0:
                v = vals[-1]
            else:
                v = (vals[-2] * wts[-2] + vals[-1] * wts[-1]) / (wts[-2] + wts[-1])
            wt, ln = wts[-2] + wts[-1], lens[-2] + lens[-1]
            del vals[-1], wts[-1], lens[-1]
            vals[-1], wts[-1], lens[-1] = v, wt, ln
    out = np.repeat(vals, lens).astype(float)
    filled = np.flatnonzero(np.asarray(w) > 0)
    if len(filled):                      # trailing empty bins keep the last populated value
        out[filled[-1] + 1:] = out[filled[-1]]
    return out


def fit_curve(mode: int, scores: np.ndarray, labels: np.ndarray, edges: np.ndarray = DEFAULT_EDGES) -> ModeCurve:
    s = np.asarray(scores, dtype=float)
    y = np.asarray(labels, dtype=bool)
    s = np.maximum(s, edges[0])
    b = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(edges) - 1)
    nb = len(edges)
    pos = np.bincount(b, weights=y.astype(float), minlength=nb)
    tot = np.bincount(b, minlength=nb).astype(float)
    raw = np.divide(pos, tot, out=np.zeros(nb), where=tot > 0)
    p = isotonic(raw, tot)
    # empty top bins inherit the last populated value (isotonic pools them forward)
    certain = np.flatnonzero(p >= 1.0 - 1e-12)
    if len(certain) and y.any() and (~y).any():
        threshold = float(max(edges[certain[0]], np.max(s[~y]) + 1e-9))
    elif len(certain) and not (~y).any():
        threshold = float(edges[certain[0]])
    else:
        threshold = math.inf
    return ModeCurve(mode, np.asarray(edges, float), p, pos, tot, threshold)


@dataclass
class LoopModel:
    overlap_threshold: float = 0.33
    curves: dict[int, ModeCurve] = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    # When set, a candidate is a loop only if the overlap implied by its verified transform (MatchResult.overlap)
    # is at least this, and the curves were fitted on such pairs only: the local score then no longer has to
    # separate a true loop on a feature-poor floor from a near miss (J just under r) on a feature-rich one.
    min_overlap: float | None = None

    def probability(self, mode: int, score: float | np.ndarray) -> float | np.ndarray:
        return self._curve(mode).prob(score)

    def threshold(self, mode: int) -> float:
        return self._curve(mode).threshold

    def _curve(self, mode: int) -> ModeCurve:
        if mode not in self.curves:
            raise KeyError(f"the loop model has no curve for mode {mode} (has {sorted(self.curves)})")
        return self.curves[mode]

    # ------------------------------------------------------------------ I/O
    def to_dict(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "overlap_threshold": self.overlap_threshold,
                "score": "local", "min_overlap": self.min_overlap, "provenance": self.provenance,
                "modes": {str(m): {"threshold": (c.threshold if math.isfinite(c.threshold) else None),
                                   "edges": c.edges.tolist(), "probability": c.probability.round(6).tolist(),
                                   "positives": c.positives.astype(int).tolist(),
                                   "totals": c.totals.astype(int).tolist()}
                          for m, c in sorted(self.curves.items())}}

    def save(self, path: str | Path) -> None:
        atomic_write_text(path, json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "LoopModel":
        p = Path(path)
        try:
            d = json.loads(p.read_text())
        except json.JSONDecodeError as exc:
            raise LoopsError(f"{p}: not a loop model (invalid JSON at line {exc.lineno}: {exc.msg})") from None
        return cls.from_dict(d, str(p))

    @classmethod
    def from_dict(cls, d: dict, source: str = "loop model") -> "LoopModel":
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise LoopsError(f"{source}: not a loop model (field 'format' must be {FORMAT!r})")
        if d.get("version") != VERSION:
            raise LoopsError(f"{source}: unsupported loop model version {d.get('version')!r}")
        curves = {}
        modes = d.get("modes") or {}
        if not isinstance(modes, dict):
            raise LoopsError(f"{source}: field 'modes' must map a mode to its curve")
        for key, c in modes.items():
            try:
                m = int(key)
                edges = np.asarray(c["edges"], float)
                prob = np.asarray(c["probability"], float)
                pos = np.asarray(c.get("positives", np.zeros(len(prob))), float)
                tot = np.asarray(c.get("totals", np.zeros(len(prob))), float)
                thr = math.inf if c["threshold"] is None else float(c["threshold"])
            except (KeyError, TypeError, ValueError, OverflowError) as exc:
                raise LoopsError(f"{source}: mode {key}: bad or missing field ({exc})") from None
            if m not in MODES or any(a.ndim != 1 for a in (edges, prob, pos, tot)) or len(edges) == 0 or \
                    not (len(pos) == len(tot) == len(prob)) or not np.all(np.isfinite(edges)) or math.isnan(thr):
                raise LoopsError(f"{source}: mode {key}: mode 1-6 with equally long finite 'edges', 'probability', "
                                 "'positives', 'totals' lists and a number or null 'threshold' expected")
            if len(edges) != len(prob) or np.any(np.diff(edges) <= 0) or np.any((prob < 0) | (prob > 1)):
                raise LoopsError(f"{source}: mode {key}: edges must increase and match the probabilities in [0, 1]")
            curves[m] = ModeCurve(m, edges, prob, pos, tot, thr)
        mo = d.get("min_overlap")
        if mo is not None and not (isinstance(mo, (int, float)) and not isinstance(mo, bool) and 0.0 <= mo <= 1.0):
            raise LoopsError(f"{source}: field 'min_overlap' must be null or a number in [0, 1], got {mo!r}")
        ot = d.get("overlap_threshold", 0.33)
        if isinstance(ot, bool) or not isinstance(ot, (int, float)) or not 0.0 < ot <= 1.0:
            raise LoopsError(f"{source}: field 'overlap_threshold' must be a number in (0, 1], got {ot!r}")
        prov = d.get("provenance", {})
        return cls(float(ot), curves, prov if isinstance(prov, dict) else {}, None if mo is None else float(mo))

    @classmethod
    def default(cls) -> "LoopModel":
        """The shipped model, trained on simulated floors (docs/loops.md gives the command)."""
        return cls.load(DEFAULT_MODEL)
