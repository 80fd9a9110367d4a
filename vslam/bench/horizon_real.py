"""Real pairs of `vslam bench horizon`: 1D SURF (one band, and several bands) against full-image ORB + RANSAC.

Pairs (all real images, ../shared/data): the Milford corridor (query traverse vs reference traverse, 160x120; a
query matches its ground-truth references i-2..i+2; four far references, at least 15 places away, per query are
non-matches) and the KITTI pairs of ../shared/data/pairs (horizon row 183). The horizon of the corridor frames is
their middle row.

Split (deterministic): corridor pairs by the parity of the query index, KITTI pairs by the parity of their line
in pairs.txt. Even = tuning half (the `bands` preset was chosen there), odd = reporting half.

Time per pair = extraction of both images + matching (medians over the calls), single-threaded OpenCV; each
method in the same run. ORB is run at the native size and with the small corridor frames upscaled 3x (the larger
images give ORB more keypoints and a much better AUC, at a higher cost).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from loops.curves import auc
from loops.horizon import HorizonParams, extract_bands, extract_features, match, match_bands
from vslam.evaluation.tables import format_table

KITTI_ROW = 183.0
FAR_PLACES = 15       # corridor references at least this many places from the query are non-matches
NEGATIVES_PER_QUERY = 4


@dataclass
class RealBank:
    images: dict[str, np.ndarray]
    rows: dict[str, float]
    pairs: list[tuple[str, str]]
    labels: np.ndarray     # (P,) bool
    half: np.ndarray       # (P,) 0 = tuning, 1 = reporting
    source: np.ndarray     # (P,) "corridor" / "kitti"


def _gray(path: Path) -> np.ndarray:
    im = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if im is None:
        raise ValueError(f"{path}: cannot read the image")
    return im


def build_real_bank(data: Path) -> RealBank:
    images, rows, pairs, labels, half, source = {}, {}, [], [], [], []
    c = data / "places" / "corridor"
    refs, qs = sorted((c / "ref").glob("*.jpg")), sorted((c / "query").glob("*.jpg"))
    for p in refs:
        images["ref/" + p.name] = _gray(p)
    for p in qs:
        images["query/" + p.name] = _gray(p)
    n = len(refs)
    for qi, ks in np.load(c / "ground_truth_new.npy", allow_pickle=True):
        qi = int(qi)
        q = "query/" + qs[qi].name
        cands = [(int(k), True) for k in ks]
        # deterministic far references: spread over the traverse
        cands += [(j, False) for j in ((qi + 20 + 23 * k) % n for k in range(NEGATIVES_PER_QUERY))
                  if abs(j - qi) >= FAR_PLACES]
        for j, lab in cands:
            pairs.append((q, "ref/" + refs[j].name))
            labels.append(lab)
            half.append(qi % 2)
            source.append("corridor")
    for k in images:
        rows[k] = images[k].shape[0] / 2.0
    pd = data / "pairs"
    for i, line in enumerate((pd / "pairs.txt").read_text().splitlines()):
        a = line.split()
        if len(a) == 3 and a[0].startswith("kitti") and a[1].startswith("kitti"):
            for name in a[:2]:
                images[name] = _gray(pd / "images" / f"{name}.png")
                rows[name] = KITTI_ROW
            pairs.append((a[0], a[1]))
            labels.append(a[2] == "1")
            half.append(i % 2)
            source.append("kitti")
    return RealBank(images, rows, pairs, np.array(labels, bool), np.array(half), np.array(source))


class OrbRansac:
    """Full-image ORB (OpenCV), ratio test 0.8, RANSAC homography (5 px at the native size): the score is the
    number of inliers."""

    def __init__(self, n_features: int = 1000, upscale: float = 1.0, small: int = 200):
        self.orb = cv2.ORB_create(n_features)
        self.bf = cv2.BFMatcher(cv2.NORM_HAMMING)
        self.upscale, self.small = upscale, small

    def extract(self, image: np.ndarray):
        if self.upscale != 1.0 and image.shape[0] < self.small:
            image = cv2.resize(image, None, fx=self.upscale, fy=self.upscale, interpolation=cv2.INTER_LINEAR)
        return self.orb.detectAndCompute(image, None)

    def match(self, fa, fb) -> float:
        (ka, da), (kb, db) = fa, fb
        if da is None or db is None or len(da) < 2 or len(db) < 2:
            return 0.0
        good = [m[0] for m in self.bf.knnMatch(da, db, k=2) if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
        if len(good) < 4:
            return 0.0
        pa = np.float32([ka[m.queryIdx].pt for m in good])
        pb = np.float32([kb[m.trainIdx].pt for m in good])
        _, mask = cv2.findHomography(pa, pb, cv2.RANSAC, 5.0 * self.upscale)
        return 0.0 if mask is None else float(mask.sum())


def _timed_scores(bank: RealBank, extract, match_fn) -> tuple[np.ndarray, float, float]:
    """Scores of every pair; median extraction and matching seconds."""
    feats, t_ext, t_match, scores = {}, [], [], []
    clock = time.perf_counter
    for k, im in bank.images.items():
        t0 = clock()
        feats[k] = extract(im, bank.rows[k])
        t_ext.append(clock() - t0)
    for a, b in bank.pairs:
        t0 = clock()
        scores.append(match_fn(feats[b], feats[a]))
        t_match.append(clock() - t0)
    return np.asarray(scores, float), float(np.median(t_ext)), float(np.median(t_match))


def methods(bands_params: HorizonParams) -> dict:
    """name -> (extract(image, row), match(test, stored) -> score)."""
    paper = HorizonParams.preset("paper")
    orb, orb3 = OrbRansac(), OrbRansac(upscale=3.0)
    return {
        "1D SURF, paper (1 band, NN+RANSAC)": (lambda im, r: extract_features(im, r, paper),
                                               lambda t, s: match(t, s, paper).score_ransac),
        f"1D SURF, {bands_params.bands} bands (NN+RANSAC, summed)": (
            lambda im, r: extract_bands(im, r, bands_params),
            lambda t, s: match_bands(t, s, bands_params).score_ransac),
        "ORB(1000) + RANSAC, native size": (lambda im, r: orb.extract(im), orb.match),
        "ORB(1000) + RANSAC, corridor upscaled 3x": (lambda im, r: orb3.extract(im), orb3.match),
    }


def real_pairs_table(data: Path, bands_params: HorizonParams) -> tuple[str, dict]:
    cv2.setNumThreads(1)
    bank = build_real_bank(data)
    y, rep, tune = bank.labels, bank.half == 1, bank.half == 0
    res, rows = {}, []
    for name, (ext, mat) in methods(bands_params).items():
        s, te, tm = _timed_scores(bank, ext, mat)
        per_pair = 2 * te + tm
        res[name] = {"auc_reporting": auc(s[rep], y[rep]), "auc_tuning": auc(s[tune], y[tune]),
                     "auc_reporting_corridor": auc(s[rep & (bank.source == "corridor")],
                                                   y[rep & (bank.source == "corridor")]),
                     "extraction_ms": te * 1e3, "matching_ms": tm * 1e3, "ms_per_pair": per_pair * 1e3}
    orb_ms = res["ORB(1000) + RANSAC, native size"]["ms_per_pair"]
    orb3_ms = res["ORB(1000) + RANSAC, corridor upscaled 3x"]["ms_per_pair"]
    for name, r in res.items():
        rows.append([name, r["auc_reporting"], r["auc_reporting_corridor"], r["auc_tuning"], r["extraction_ms"],
                     r["matching_ms"], r["ms_per_pair"], r["ms_per_pair"] / orb_ms, r["ms_per_pair"] / orb3_ms])
    n_rep, n_tune = int(rep.sum()), int(tune.sum())
    table = format_table(["method", "AUC, reporting half", "AUC, reporting, corridor only", "AUC, tuning half",
                          "extraction ms", "matching ms", "ms / pair (2 extractions + match)",
                          "time / ORB native", "time / ORB 3x"], rows, floatfmt=".3g")
    head = (f"Real pairs: {len(bank.pairs)} ({int(y.sum())} same place / {int((~y).sum())} different), "
            f"reporting half {n_rep} pairs (odd query / line), tuning half {n_tune}.")
    return f"{head}\n\n{table}", {"pairs": len(bank.pairs), "reporting": n_rep, "tuning": n_tune, "methods": res}
