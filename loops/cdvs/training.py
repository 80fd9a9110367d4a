"""Offline training of the small parameter file `loops/data/cdvs_trained.npz`.

    python -m loops.cdvs.training --shared ../shared/data [--out loops/data/cdvs_trained.npz] [--seed 0]
        [--floors DIR ...]

Training images: the real ground textures and the KITTI snippet of an unidentified sequence 00-02 drive in
../shared/data (never the 48 evaluation pairs, nor the KITTI 06 snippet whose frames appear in them), optionally
simulated floor sequences. Same-scene pairs are made by random homographies (rotation, scale, mild perspective,
shift), noise and contrast changes, so the keypoint correspondences are known exactly.

Learned: (1) relevance tables P(correctly matched | response, level, radius) for feature selection, (2) the
priority order of the 256 ORB bits (discriminative gap between matching and random pairs, decorrelated greedily),
(3) a 64-word binary codebook (k-majority), per-cluster bit means and a 32-D PCA of the residuals for the global
descriptor, (4) the global-score weights T[h], (5) per-mode pair decision thresholds: the highest local and global
scores seen on different-scene training pairs involving a real photograph, times a safety margin.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from loops.cdvs.codec import decode, encode_features
from loops.cdvs.extract import detector_for, extract_features, keypoint_attributes, processed_size, to_gray_u8
from loops.cdvs.global_desc import aggregate
from loops.cdvs.match import match
from loops.cdvs.params import MODES, CdvsParams, ExtractionParams
from loops.cdvs.trained import DEFAULT_TRAINED, N_BITS, compute_params_id, forget_loaded, load_trained, save_trained
from loops.hamming import bit_distances, hamming_matrix

N_CLUSTERS = 64
RESP_EDGES = np.array([-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0])
RADIUS_EDGES = np.linspace(0.1, 0.9, 9)
NEGATIVES_PER_IMAGE = 8   # different-scene pairs per training image (the maximum is a tail statistic: many needed)
LOCAL_MARGIN = 1.3
GLOBAL_MARGIN = 1.15


# ---------------------------------------------------------------------------------------------- training images
def training_images(shared: Path, floors: list[Path], rng: np.random.Generator) -> list[tuple[str, np.ndarray]]:
    out: list[tuple[str, np.ndarray]] = []
    for p in sorted((shared / "textures").rglob("*")):
        if p.suffix.lower() in (".png", ".jpg"):
            im = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
            if im is not None:
                out.append((f"textures/{p.parent.name}/{p.name}", im))
    kitti = shared / "places" / "kitti_snippets" / "KITTI_sequence_2_unidentified_seq00-02calib" / "image_l"
    for p in sorted(kitti.glob("*.png"))[::2]:
        out.append((f"kitti_seq2/{p.name}", cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)))
    corridor = shared / "places" / "corridor" / "ref"
    for p in sorted(corridor.glob("*.jpg"))[::3]:
        im = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        out.append((f"corridor/ref/{p.name}", cv2.resize(im, None, fx=3, fy=3, interpolation=cv2.INTER_CUBIC)))
    for d in floors:
        rows = list(csv.DictReader(open(d / "frames.csv")))
        for r in rows[:: max(1, len(rows) // 20)]:
            out.append((f"floor/{d.name}/{r['image']}", cv2.imread(str(d / r["image"]), cv2.IMREAD_GRAYSCALE)))
    return [(n, im) for n, im in out if im is not None]


def random_warp(img: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A random same-scene view and the homography (processed pixels of img -> view)."""
    h, w = img.shape
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    th = rng.uniform(-np.pi, np.pi)
    s = np.exp(rng.uniform(np.log(0.75), np.log(1.35)))
    R = np.array([[s * np.cos(th), -s * np.sin(th)], [s * np.sin(th), s * np.cos(th)]])
    t = c - R @ c + rng.uniform(-0.3, 0.3, 2) * [w, h]
    H = np.eye(3)
    H[:2, :2], H[:2, 2] = R, t
    P = np.eye(3)
    P[2, :2] = rng.uniform(-3e-4, 3e-4, 2)
    H = H @ np.linalg.inv(np.array([[1, 0, -c[0]], [0, 1, -c[1]], [0, 0, 1]])) @ P @ \
        np.array([[1, 0, -c[0]], [0, 1, -c[1]], [0, 0, 1]])
    # re-centre the perspective part around the image centre (keeps the view overlapping)
    H /= H[2, 2]
    view = cv2.warpPerspective(img, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    gain, gamma = rng.uniform(0.7, 1.3), rng.uniform(0.8, 1.25)
    v = 255.0 * (np.clip(view * gain, 0, 255) / 255.0) ** gamma + rng.normal(0, rng.uniform(1, 4), view.shape)
    if rng.random() < 0.4:
        v = cv2.GaussianBlur(v, (0, 0), rng.uniform(0.5, 1.2))
    return np.clip(v, 0, 255).astype(np.uint8), H


def prepare(img: np.ndarray, max_side: int) -> np.ndarray:
    g = to_gray_u8(img)
    pw, ph = processed_size(g.shape[1], g.shape[0], max_side)
    return cv2.resize(g, (pw, ph), interpolation=cv2.INTER_AREA) if (pw, ph) != g.shape[::-1] else g


def describe_all(gray: np.ndarray, ex: ExtractionParams):
    orb = detector_for(gray, ex)
    kps = orb.detect(gray, None)
    med = np.median([k.response for k in kps]) if kps else 1.0
    kps, desc = orb.compute(gray, kps)
    if desc is None or not kps:
        return None
    xy, _, octave, radius = keypoint_attributes(kps, gray.shape[::-1])
    resp = np.array([k.response for k in kps])
    lresp = np.log(np.maximum(resp, 1e-12) / max(med, 1e-12))
    return xy, lresp, octave, radius, desc


# ---------------------------------------------------------------------------------------------- learning steps
def k_majority(desc: np.ndarray, k: int, rng: np.random.Generator, iterations: int = 12) -> np.ndarray:
    """Binary k-means with Hamming distance and majority-vote centroids (k-means++ seeding)."""
    n = len(desc)
    centres = [desc[rng.integers(n)]]
    dmin = np.full(n, np.inf)
    for _ in range(1, k):
        d = cv2.batchDistance(desc, centres[-1][None], cv2.CV_32S, normType=cv2.NORM_HAMMING, K=1)[0].ravel()
        dmin = np.minimum(dmin, d.astype(np.float64))
        p = dmin ** 2
        centres.append(desc[rng.choice(n, p=p / p.sum())])
    cb = np.array(centres)
    bits = np.unpackbits(desc, axis=1)
    for _ in range(iterations):
        _, a = cv2.batchDistance(desc, cb, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=1)
        a = a.ravel()
        for c in range(k):
            m = a == c
            if m.any():
                cb[c] = np.packbits(bits[m].mean(axis=0) > 0.5)
            else:
                cb[c] = desc[rng.integers(n)]
    return cb


def greedy_bit_order(p_match: np.ndarray, p_random: np.ndarray, bits: np.ndarray) -> np.ndarray:
    gap = p_random - p_match
    corr = np.abs(np.corrcoef(bits.T.astype(np.float64)))
    np.fill_diagonal(corr, 0)
    corr = np.nan_to_num(corr)
    chosen = [int(np.argmax(gap))]
    maxc = corr[chosen[0]].copy()
    left = np.ones(N_BITS, dtype=bool)
    left[chosen[0]] = False
    while left.any():
        score = np.where(left, gap * (1 - maxc), -np.inf)
        b = int(np.argmax(score))
        chosen.append(b)
        left[b] = False
        maxc = np.maximum(maxc, corr[b])
    return np.array(chosen, dtype=np.int16)


def binned_rate(values: np.ndarray, labels: np.ndarray, edges: np.ndarray | None, n_bins: int) -> np.ndarray:
    idx = np.searchsorted(edges, values) if edges is not None else np.clip(values, 0, n_bins - 1)
    pos = np.bincount(idx, weights=labels.astype(float), minlength=n_bins)
    tot = np.bincount(idx, minlength=n_bins).astype(float)
    rate = (pos + 1.0) / (tot + 4.0)               # Laplace-smoothed
    return (rate / rate.max()).astype(np.float32)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(DEFAULT_TRAINED))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--floors", nargs="*", default=[], help="simulated sequence directories to add")
    ap.add_argument("--shared", required=True, help="the shared data folder (../shared/data beside the checkout)")
    args = ap.parse_args(argv)
    shared = Path(args.shared)
    rng = np.random.default_rng(args.seed)
    ex = ExtractionParams()
    t0 = time.time()
    images = training_images(shared, [Path(f) for f in args.floors], rng)
    print(f"{len(images)} training images", file=sys.stderr)
    grays = [prepare(im, ex.max_side) for _, im in images]
    # scene groups: images of one sequence may overlap, so different-scene pairs come from different groups
    groups = [n.rsplit("/", 1)[0] if not n.startswith("textures/") else n for n, _ in images]

    # ---- same-scene pairs with known homographies: relevance labels and bit statistics
    attrs, labels, xor_match, all_desc = [], [], [], []
    views = []
    for g in grays:
        view, H = random_warp(g, rng)
        views.append(view)
        fa, fb = describe_all(g, ex), describe_all(view, ex)
        if fa is None or fb is None:
            continue
        xa, lra, oa, ra, da = fa
        xb, _, _, _, db = fb
        proj = cv2.perspectiveTransform(xa.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
        dist = np.linalg.norm(proj[:, None, :] - xb[None, :, :], axis=2)
        gt = dist.argmin(axis=1)
        has_gt = dist[np.arange(len(xa)), gt] < 3.0
        hd = hamming_matrix(da, db).astype(np.float32)
        nn = hd.argmin(axis=1)
        srt = np.sort(hd, axis=1)
        ratio_ok = srt[:, 0] <= 0.85 * srt[:, 1]
        lab = has_gt & (nn == gt) & ratio_ok
        # relevance = P(correct match | attributes, the point is visible in both views): without the visibility
        # condition the tables would learn "prefer the image centre", wrong for loops whose overlap is off-centre
        h, w = view.shape
        visible = np.all((proj >= 16) & (proj < [w - 16, h - 16]), axis=1)
        attrs.append(np.column_stack([lra, oa, ra, visible]))
        labels.append(lab)
        ia = np.flatnonzero(has_gt)
        xor_match.append(np.unpackbits(da[ia] ^ db[gt[ia]], axis=1))
        all_desc.append(da)
    A = np.concatenate(attrs)
    L = np.concatenate(labels)
    vis = A[:, 3] > 0
    resp_p = binned_rate(A[vis, 0], L[vis], RESP_EDGES, len(RESP_EDGES) + 1)
    octave_p = binned_rate(A[vis, 1].astype(int), L[vis], None, ex.n_levels)
    radius_p = binned_rate(A[vis, 2], L[vis], RADIUS_EDGES, len(RADIUS_EDGES) + 1)
    # with visibility folded in, the radius table also learns "the centre is more often in the other view":
    # right for photographs of an object, wrong for loops on a floor where the overlap can be anywhere
    radius_p_central = binned_rate(A[:, 2], L, RADIUS_EDGES, len(RADIUS_EDGES) + 1)
    D = np.concatenate(all_desc)
    bits = np.unpackbits(D, axis=1)
    p_match = np.concatenate(xor_match).mean(axis=0)
    i, j = rng.integers(len(D), size=(2, 50000))
    p_random = np.unpackbits(D[i] ^ D[j], axis=1).mean(axis=0)
    sub = rng.choice(len(D), size=min(len(D), 30000), replace=False)
    bit_order = greedy_bit_order(p_match, p_random, bits[sub])
    print(f"relevance/bits done: {len(D)} descriptors, {L.mean():.2f} matched ({time.time() - t0:.0f} s)",
          file=sys.stderr)

    # ---- global descriptor: codebook, residual PCA
    sub = rng.choice(len(D), size=min(len(D), 40000), replace=False)
    codebook = k_majority(D[sub], N_CLUSTERS, rng)
    _, a = cv2.batchDistance(D[sub], codebook, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=1)
    a = a.ravel()
    xb = bits[sub].astype(np.float32)
    cluster_mean = np.stack([xb[a == c].mean(axis=0) if np.any(a == c) else np.full(N_BITS, 0.5, np.float32)
                             for c in range(N_CLUSTERS)]).astype(np.float32)
    resid = xb - cluster_mean[a]
    cov = np.cov(resid.T.astype(np.float64))
    evals, evecs = np.linalg.eigh(cov)
    projection = evecs[:, ::-1][:, :32].astype(np.float32)
    projection *= np.sign(projection[np.abs(projection).argmax(axis=0), np.arange(32)])  # deterministic signs
    print(f"codebook done ({time.time() - t0:.0f} s)", file=sys.stderr)

    arrays = dict(bit_order=bit_order, resp_edges=RESP_EDGES.astype(np.float32), resp_p=resp_p, octave_p=octave_p,
                  radius_edges=RADIUS_EDGES.astype(np.float32), radius_p=radius_p,
                  radius_p_central=radius_p_central, codebook=codebook,
                  cluster_mean=cluster_mean.astype(np.float16).astype(np.float32), projection=projection,
                  global_weights=np.ones(33, np.float32), local_threshold=np.zeros(6, np.float32),
                  global_threshold=np.zeros(6, np.float32))
    provenance = {"command": "python -m loops.cdvs.training " + " ".join(argv if argv is not None else sys.argv[1:]),
                  "seed": args.seed, "images": [n for n, _ in images],
                  "note": "same-scene pairs are random homographies of these images; different-scene pairs are "
                          "distinct images. The 48 evaluation pairs and the KITTI 06 snippet are never used."}
    out = Path(args.out)
    save_trained(out, arrays, provenance)

    # ---- global weights T[h] from common clusters of same vs different pairs (needs the codebook just saved)
    forget_loaded()
    tr = load_trained(out)
    hs_same, hs_diff = np.zeros(33), np.zeros(33)
    glob = []
    for g, v in zip(grays, views):
        fa, fb = describe_all(g, ex), describe_all(v, ex)
        ga = aggregate(fa[4][:ex.n_described], tr, N_CLUSTERS) if fa else None
        gb = aggregate(fb[4][:ex.n_described], tr, N_CLUSTERS) if fb else None
        glob.append((ga, gb))
    for k, (ga, gb) in enumerate(glob):
        if ga is None or gb is None:
            continue
        c = ga[0] & gb[0]
        hs_same += np.bincount(bit_distances(ga[1][c], gb[1][c]), minlength=33)
        o = glob[other_group(groups, k, rng)][1]
        if o is not None:
            c = ga[0] & o[0]
            hs_diff += np.bincount(bit_distances(ga[1][c], o[1][c]), minlength=33)
    ps, pd = (hs_same + 1) / (hs_same.sum() + 33), (hs_diff + 1) / (hs_diff.sum() + 33)
    omega = ps / (ps + pd)
    hh = np.arange(33)
    weights = (32 - 2 * hh) / 32.0 * omega
    # never score a closer pair of signatures lower than a farther one (identical > overlapping > disjoint): where
    # different-scene clusters also often agree exactly, the raw table dips at small h
    weights = np.maximum.accumulate(weights[::-1])[::-1].astype(np.float32)
    arrays["global_weights"] = weights
    save_trained(out, arrays, provenance)
    forget_loaded()
    print(f"global weights done ({time.time() - t0:.0f} s)", file=sys.stderr)

    # ---- per-mode pair decision thresholds from different-scene training pairs
    thresholds = pair_thresholds(grays, groups, out, rng)
    arrays["local_threshold"] = thresholds[0]
    arrays["global_threshold"] = thresholds[1]
    provenance["pair_threshold_margins"] = {"local": LOCAL_MARGIN, "global": GLOBAL_MARGIN}
    provenance["params_id"] = compute_params_id(arrays)
    save_trained(out, arrays, provenance)
    forget_loaded()
    print(json.dumps({"local_threshold": thresholds[0].tolist(), "global_threshold": thresholds[1].tolist()}),
          file=sys.stderr)
    print(f"wrote {out} ({out.stat().st_size} bytes, {time.time() - t0:.0f} s)", file=sys.stderr)
    return 0


def may_share_content(a: str, b: str) -> bool:
    """Scene groups that can show the same surface: one group, a simulated floor and a texture photograph (floors
    are rendered from those photographs), or two floors of the wood family (same wood photographs)."""
    kinds = {a.split("/")[0], b.split("/")[0]}
    woods = sum("wood" in g for g in (a, b)) == 2
    return a == b or kinds == {"floor", "textures"} or (kinds == {"floor"} and woods)


def other_group(groups: list[str], k: int, rng: np.random.Generator) -> int:
    """A random image index from a scene group that cannot share content with image k's."""
    cand = [i for i, g in enumerate(groups) if not may_share_content(g, groups[k])]
    return int(cand[rng.integers(len(cand))])


def pair_thresholds(grays, groups, path: Path, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    tr = load_trained(path)
    ex = ExtractionParams()
    feats = [extract_features(g, ex, tr) for g in grays]
    n = len(grays)
    # the photograph preset's thresholds: negatives that involve at least one real photograph (simulated floors
    # are renders of a few texture photographs; floors get their thresholds from the loop model instead)
    diff_pairs = [(k, other_group(groups, k, rng)) for k in range(n) for _ in range(NEGATIVES_PER_IMAGE)]
    diff_pairs = [(a, b) for a, b in diff_pairs if not (groups[a].startswith("floor/") and groups[b].startswith("floor/"))]
    lt, gt = np.zeros(6, np.float32), np.zeros(6, np.float32)
    for m in MODES:
        p = CdvsParams.for_mode(m)
        ds = [decode(encode_features(f, p, tr)) for f in feats]
        ls, gs = [], []
        for a, b in diff_pairs:
            r = match(ds[a], ds[b], p.matching, tr)
            ls.append(r.local_score)
            gs.append(r.global_score)
        lt[m - 1] = max(LOCAL_MARGIN * max(ls), 1.0)
        gt[m - 1] = GLOBAL_MARGIN * max(gs)
        print(f"mode {m}: {len(ls)} different-scene pairs, local max {max(ls):.2f}, global max {max(gs):.3f}",
              file=sys.stderr)
    return lt, gt


if __name__ == "__main__":
    sys.exit(main())
