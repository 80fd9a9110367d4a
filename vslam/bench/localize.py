"""`vslam bench localize`: visual-memory localisation on real image sets, in the paper's table layout.

Sets (from ../shared/data): corridor (reference traverse = memory, second traverse = queries), corridor-rot (the
same queries rotated by 10-30 degrees, alternating sign, seeded), kitti (two KITTI snippets, every 3rd frame a key
image), pairs (the 48 labelled pairs: one key image per scene). Every descriptor runs on every set, beside the
`pydbow` package on the same images and the same (ORB / BRIEF) descriptors. Then: the BRIEFROT theta sweep (Fig. 11),
repeatability over vocabulary rebuilds (Table 8) and the query time against a 1000-image 640x480 memory.
Prints markdown tables, writes JSON and PNG plots into --out.

Each image's descriptors are extracted once per descriptor (and pattern angle) and reused by every stage; each
vocabulary is built once per (key images, parameters, seed) and reused (corridor and corridor-rot share their key
images, BRIEFROT's unrotated vocabulary is the BRIEF vocabulary of the same seed). The time per query is still
extraction + scoring: each query's extraction time is recorded when it is first extracted.
"""
from __future__ import annotations

import argparse
import datetime
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

NAME = "localize"
HELP = "visual-memory localisation: paper tables on real sets, pydbow comparison, repeatability, query time"
ALL_DESCRIPTORS = ("brief", "briefrot", "orb", "surf", "color-random", "color-whole", "color-half")
SETS = ("corridor", "corridor-rot", "kitti", "pairs")
REPEAT_DESCRIPTORS = ("brief", "briefrot", "color-random", "orb", "surf")   # the rows of the paper's Table 8
REPEAT_SETS = ("corridor", "kitti", "pairs")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="smaller run (~ a few minutes): fewer queries, builds, angles")
    p.add_argument("--out", default="bench-out/localize", help="output folder for JSON, CSV truth files and plots")
    p.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS))
    p.add_argument("--descriptors", nargs="+", choices=ALL_DESCRIPTORS, default=list(ALL_DESCRIPTORS))
    p.add_argument("--preset", default="paper", help="vocabulary preset (paper: k=8, L=8 as in the paper; default; fast)")
    p.add_argument("--no-pydbow", action="store_true", help="skip the pydbow comparison")
    p.add_argument("--skip", nargs="*", default=[], choices=("sets", "sweep", "repeat", "timing"),
                   help="parts to skip")
    p.add_argument("--builds", type=int, help="vocabulary builds per descriptor for repeatability (default 30; "
                                              "quick 10; the paper used 100)")
    p.add_argument("--timing-images", type=int, help="memory size for the query-time target (default 1000)")
    p.add_argument("--repeat-study", action="store_true",
                   help="instead of the tables: repeatability and Recall@1 of BRIEF / BRIEFROT under vocabulary-build "
                        "options (Lloyd iterations, k-means++ restarts, more descriptors)")


# ---- data sets ---------------------------------------------------------------------------------------------------
@dataclass
class PlaceSet:
    name: str
    note: str
    keys: list      # [(name, image)]
    queries: list   # [(name, image, mask or None)]
    truth: dict     # query name -> [key indices]
    keys_id: str    # identity of the key images (sets with equal keys_id share features and vocabularies)
    queries_id: str
    min_side: int = 0
    grayscale: bool = False

    @property
    def key_names(self) -> list[str]:
        return [n for n, _ in self.keys]


def _imread(path: Path) -> np.ndarray:
    from vslam.cli.cmd_localize import read_image

    return read_image(path)


def rotate_with_mask(image: np.ndarray, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Rotate about the centre (OpenCV sign: positive = counter-clockwise) keeping the size; the mask marks the
    pixels that come from the image (eroded, so no keypoint sits on the new black border)."""
    import cv2

    h, w = image.shape[:2]
    m = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), angle_deg, 1.0)
    out = cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    mask = cv2.warpAffine(np.full((h, w), 255, np.uint8), m, (w, h), flags=cv2.INTER_NEAREST)
    return out, cv2.erode(mask, np.ones((5, 5), np.uint8))


def rotation_angles(n: int, seed: int = 7, lo: float = 10.0, hi: float = 30.0) -> np.ndarray:
    """Deterministic query rotations: magnitudes uniform in [lo, hi] degrees, signs alternating."""
    mags = np.random.default_rng(seed).uniform(lo, hi, n)
    return mags * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)


def corridor_set(data: Path, rotated: bool = False, stride: int = 1) -> PlaceSet:
    d = data / "places" / "corridor"
    refs, qs = sorted((d / "ref").glob("*.jpg")), sorted((d / "query").glob("*.jpg"))
    gt = np.load(d / "ground_truth_new.npy", allow_pickle=True)
    keys = [(p.name, _imread(p)) for p in refs]
    truth, queries = {}, []
    angles = rotation_angles(len(qs))
    for qi, ks in gt:
        if qi % stride:
            continue
        p = qs[int(qi)]
        img, mask = _imread(p), None
        if rotated:
            img, mask = rotate_with_mask(img, float(angles[int(qi)]))
        queries.append((p.name, img, mask))
        truth[p.name] = [int(k) for k in ks]
    note = ("Milford corridor, 111 ref keys vs second traverse, truth = ref i-2..i+2; 160x120 frames upscaled to "
            "480 lines (the paper's image height)")
    if rotated:
        note += "; queries rotated by 10-30 deg (alternating sign, seed 7), black borders masked"
    return PlaceSet("corridor-rot" if rotated else "corridor", note, keys, queries, truth, "corridor/ref",
                    f"corridor/query{'-rot' if rotated else ''}/{stride}", min_side=480)


def kitti_set(data: Path, key_every: int = 3, radius_m: float = 3.0) -> PlaceSet:
    root = data / "places" / "kitti_snippets"
    keys, queries, truth = [], [], {}
    for seq in sorted(p for p in root.glob("KITTI_sequence_*") if p.is_dir()):
        images = sorted((seq / "image_l").glob("*.png"))
        poses = np.loadtxt(seq / "poses.txt").reshape(-1, 3, 4)[:, :, 3]
        base = len(keys)
        key_frames = [i for i in range(len(images)) if i % key_every == 0]
        keys += [(f"{seq.name[:16]}/{images[i].name}", _imread(images[i])) for i in key_frames]
        kpos = poses[key_frames]
        for i in range(len(images)):
            if i % key_every == 0:
                continue
            name = f"{seq.name[:16]}/{images[i].name}"
            dist = np.linalg.norm(kpos - poses[i], axis=1)
            near = np.nonzero(dist <= max(radius_m, dist.min()))[0]
            queries.append((name, _imread(images[i]), None))
            truth[name] = [base + int(j) for j in near]
    note = (f"two KITTI snippets (51 frames each), every {key_every}rd frame a key image, the others queries; truth = "
            f"keys of the same drive within {radius_m:g} m (ground-truth poses); grayscale")
    return PlaceSet("kitti", note, keys, queries, truth, "kitti/keys", "kitti/queries", grayscale=True)


def pairs_set(data: Path) -> PlaceSet:
    d = data / "pairs"
    parent: dict[str, str] = {}

    def find(a: str) -> str:
        while parent.setdefault(a, a) != a:
            a = parent[a]
        return a

    order: list[str] = []
    for line in (d / "pairs.txt").read_text().splitlines():
        parts = line.split()
        if len(parts) != 3:
            continue
        a, b, label = parts
        for n in (a, b):
            if n not in order:
                order.append(n)
        if label == "1":
            parent[find(b)] = find(a)
    scenes: dict[str, list[str]] = {}
    for n in order:
        scenes.setdefault(find(n), []).append(n)
    keys, queries, truth = [], [], {}
    for members in scenes.values():
        key_index = len(keys)
        keys.append((members[0], _imread(d / "images" / f"{members[0]}.png")))
        for n in members[1:]:
            queries.append((n, _imread(d / "images" / f"{n}.png"), None))
            truth[n] = [key_index]
    note = (f"{len(keys)} scenes from the labelled pairs (same-scene pairs joined): first image of a scene = its key, "
            "the others are queries; grayscale")
    return PlaceSet("pairs", note, keys, queries, truth, "pairs/keys", "pairs/queries", grayscale=True)


def load_set(name: str, data: Path, quick: bool) -> PlaceSet:
    if name == "corridor":
        return corridor_set(data, stride=3 if quick else 1)
    if name == "corridor-rot":
        return corridor_set(data, rotated=True, stride=3 if quick else 1)
    if name == "kitti":
        return kitti_set(data)
    return pairs_set(data)


def write_truth(path: Path, ps: PlaceSet) -> None:
    from odometry.shared.atomic_io import atomic_write_text

    rows = ["query,key"] + [f"{q},{ps.keys[k][0]}" for q, ks in ps.truth.items() for k in ks]
    atomic_write_text(path, "\n".join(rows) + "\n")


# ---- caches: each image's features once per descriptor, each vocabulary once per (keys, params, seed) -----------
class Features:
    """Descriptors of the bench's images per (images, index, extraction parameters, pattern angle), with the time
    their extraction took (for queries: the extraction part of the time per query)."""

    def __init__(self) -> None:
        self._d: dict[tuple, tuple[np.ndarray | None, float]] = {}

    def get(self, images_id: str, index: int, image: np.ndarray, mask, params, angles=(0.0,), name: str = "",
            cache: bool = True) -> tuple[list, float]:
        from loops.vocab import NoFeaturesError, extract, extraction_key

        ek = extraction_key(params)
        key = lambda a: (images_id, index, ek, float(a))  # noqa: E731
        missing = tuple(a for a in angles if key(a) not in self._d)
        fresh = {}
        if missing:
            t0 = time.perf_counter()
            try:
                descs = extract(image, params, mask, missing, name=name)
            except NoFeaturesError:
                descs = [None] * len(missing)
            dt = time.perf_counter() - t0
            fresh = {key(a): (d, dt) for a, d in zip(missing, descs)}
            if cache:
                self._d.update(fresh)
        got = [fresh.get(key(a)) or self._d[key(a)] for a in angles]
        return [g[0] for g in got], got[0][1]

    def keys(self, ps: PlaceSet, params, angles, cache: bool = True) -> list[list[np.ndarray]]:
        """per_angle[o][i]: descriptors of key image i under pattern angle o (raises for a featureless key)."""
        from loops.vocab import NoFeaturesError

        per_key = []
        for i, (n, im) in enumerate(ps.keys):
            descs, _ = self.get(ps.keys_id, i, im, None, params, angles, n, cache)
            if descs[0] is None:
                raise NoFeaturesError(f"{n}: no {params.descriptor.value} features in a key image")
            per_key.append(descs)
        return [[d[o] for d in per_key] for o in range(len(angles))]

    def queries(self, ps: PlaceSet, params, indices=None, cache: bool = True) -> list[tuple]:
        """(name, plain-pattern descriptors or None, extraction seconds) of the queries."""
        idx = range(len(ps.queries)) if indices is None else indices
        out = []
        for i in idx:
            n, im, mask = ps.queries[i]
            descs, dt = self.get(ps.queries_id, i, im, mask, params, (0.0,), n, cache)
            out.append((n, descs[0], dt))
        return out


class Vocabularies:
    """Vocabulary trees per (key images, extraction parameters, angle, tree parameters, seed), with build times."""

    def __init__(self) -> None:
        self._d: dict[tuple, tuple] = {}

    @staticmethod
    def key(keys_id: str, params, o: int, angle: float) -> tuple:
        from loops.vocab import extraction_key, vocabulary_seed

        return (keys_id, extraction_key(params), float(angle), params.k, params.depth, params.kmeans_iters,
                params.kmeans_restarts, params.max_train_descriptors, vocabulary_seed(params, o))

    def tree(self, keys_id: str, params, o: int, angle: float, descs: list[np.ndarray], cache: bool = True):
        from loops.vocab import build_tree

        key = self.key(keys_id, params, o, angle)
        seed = key[-1]
        if key not in self._d:
            t0 = time.perf_counter()
            tree = build_tree(np.concatenate(descs), params.k, params.depth, seed=seed, iters=params.kmeans_iters,
                              max_train=params.max_train_descriptors, restarts=params.kmeans_restarts)
            entry = (tree, time.perf_counter() - t0)
            if not cache:
                return entry
            self._d[key] = entry
        return self._d[key]

    def memory(self, keys_id: str, names, params, per_angle, angles, cache: bool = True):
        """(VisualMemory, seconds of its vocabulary builds + database)."""
        from loops.vocab import VisualMemory

        built = [self.tree(keys_id, params, o, a, per_angle[o], cache) for o, a in enumerate(angles)]
        t0 = time.perf_counter()
        memory = VisualMemory.from_trees([t for t, _ in built], per_angle, names, params, angles)
        return memory, sum(s for _, s in built) + time.perf_counter() - t0


# ---- pydbow adapter ----------------------------------------------------------------------------------------------
class PydbowMemory:
    """The `pydbow` package (PyPI, pure-Python DBoW) behind the VisualMemory query interface, fed with our
    descriptors. Its Vocabulary() runs ORB itself, so the tree is built with its own initialize_tree() on our
    descriptors instead; its k-means draws from numpy's global generator, which is seeded here. It has no notion of
    key-to-key similarity restricted to candidates (it scores every key; wrong keys ~0.5 on the pairs set), so mu2
    is not computed for it."""

    def __init__(self, key_descs: list[np.ndarray], key_names: list[str], params, k: int, depth: int,
                 max_train: int, seed: int = 0, replicate: int = 1):
        import dbow

        self.dbow, self.params = dbow, params
        train = np.concatenate(key_descs)
        rng = np.random.default_rng(seed)
        if len(train) > max_train:
            train = train[np.sort(rng.choice(len(train), max_train, replace=False))]
        np.random.seed(seed)
        voc = dbow.Vocabulary.__new__(dbow.Vocabulary)
        voc.root_node = dbow.Node([dbow.ORB.from_cv_descriptor(x) for x in train])
        voc.words = [dbow.Word.from_node(n) for n in dbow.dbow.initialize_tree(voc.root_node, k, depth)]
        n_entries = len(key_descs) * replicate
        for w in voc.words:
            w.update_weight(n_entries)
        self.db = dbow.Database(voc)
        for d in key_descs:
            self.db.add(self._convert(d))
        # its query scores every database entry densely, whatever they hold: repeating the entries gives the query
        # cost of a database `replicate` times larger without paying its (Python) insertion again
        self.db.database = self.db.database * replicate
        self.db.descriptors = self.db.descriptors * replicate
        self.key_names = [f"{n}#{r}" if replicate > 1 else n for r in range(replicate) for n in key_names]
        self.n_words = len(voc.words)

    def _convert(self, descs: np.ndarray) -> list:
        return [self.dbow.ORB.from_cv_descriptor(x) for x in descs]

    def __len__(self) -> int:
        return len(self.key_names)

    def query_descriptors(self, descs: np.ndarray):
        from loops.vocab import Ranking

        with np.errstate(invalid="ignore", divide="ignore"):
            scores = np.nan_to_num(np.asarray(self.db.query(self._convert(descs)), float), nan=0.0)
        keys = np.lexsort((np.arange(len(scores)), -scores))
        return Ranking(keys, scores[keys], np.zeros(len(keys), np.int64))


# ---- runs --------------------------------------------------------------------------------------------------------
@dataclass
class SetResult:
    rows: list = field(default_factory=list)       # (label, Summary)
    curves: dict = field(default_factory=dict)     # label -> PRCurve
    skipped: dict = field(default_factory=dict)    # descriptor -> reason
    extra: dict = field(default_factory=dict)


@dataclass
class Bench:
    base: object
    pydbow_cfg: dict | None
    features: Features = field(default_factory=Features)
    vocabs: Vocabularies = field(default_factory=Vocabularies)
    pydbow: dict = field(default_factory=dict)

    def params(self, ps: PlaceSet, desc: str, **changes):
        return self.base.replace(descriptor=desc, min_image_side=ps.min_side, **changes)

    def memory(self, ps: PlaceSet, params):
        from loops.vocab import brief_angles

        angles = brief_angles(params)
        per_angle = self.features.keys(ps, params, angles)
        return self.vocabs.memory(ps.keys_id, ps.key_names, params, per_angle, angles)

    def run_set(self, ps: PlaceSet, descriptors) -> SetResult:
        from loops.vocab import GrayscaleImageError, evaluate_descriptors

        res = SetResult()
        for desc in descriptors:
            params = self.params(ps, desc)
            try:
                memory, build_s = self.memory(ps, params)
            except GrayscaleImageError as exc:
                res.skipped[desc] = str(exc)
                continue
            ev = evaluate_descriptors(memory, self.features.queries(ps, params), ps.truth)
            s = ev.summary()
            res.rows.append((params.descriptor.label, s))
            res.curves[params.descriptor.label] = ev.pr()
            res.extra[desc] = {"vocabulary_build_s": build_s, "words": [t.n_words for t in memory.trees],
                               "top1_vocabulary_counts": ev.winner_counts(len(memory.angles)).tolist(),
                               "pattern_angles": list(memory.angles), **key_similarity_spread(memory)}
            print(f"  [{ps.name}] {params.descriptor.label}: R@1 {s.recall1:.3f}, mu1=1 {s.eff_mu1:.1f} %, "
                  f"mu2<2.5 {s.eff_mu2:.1f} %, {s.median_ms:.1f} ms/query, vocabulary {build_s:.1f} s", flush=True)
        for feat in (self.pydbow_cfg or {}).get("features", []):
            params = self.params(ps, feat)
            key = (ps.keys_id, feat)
            if key not in self.pydbow:
                cfg = self.pydbow_cfg
                t0 = time.perf_counter()
                pm = PydbowMemory(self.features.keys(ps, params, (0.0,))[0], ps.key_names, params, cfg["k"],
                                  cfg["depth"], cfg["max_train"])
                self.pydbow[key] = (pm, time.perf_counter() - t0)
            pm, build_s = self.pydbow[key]
            ev = evaluate_descriptors(pm, self.features.queries(ps, params), ps.truth)
            s = ev.summary()
            label = f"pydbow ({params.descriptor.label})"
            res.rows.append((label, s))
            res.curves[label] = ev.pr()
            res.extra[f"pydbow-{feat}"] = {"vocabulary_build_s": build_s, "words": [pm.n_words]}
            print(f"  [{ps.name}] {label}: R@1 {s.recall1:.3f}, {s.median_ms:.1f} ms/query, build {build_s:.1f} s",
                  flush=True)
        return res

    def theta_sweep(self, ps: PlaceSet, thetas) -> list[tuple]:
        """Fig. 11: BRIEFROT effectiveness against the rotation angle theta (theta = 0 degenerates to three copies of
        BRIEF, which is why the BRIEF row stands in for it)."""
        from loops.vocab import evaluate_descriptors

        rows = []
        for th in thetas:
            params = self.params(ps, "brief" if th == 0 else "briefrot", rot_theta_deg=float(th))
            memory, _ = self.memory(ps, params)
            ev = evaluate_descriptors(memory, self.features.queries(ps, params), ps.truth)
            s = ev.summary()
            rows.append((float(th), s, ev.winner_counts(len(memory.angles)).tolist()))
            print(f"  [theta sweep] theta {th:g}: R@1 {s.recall1:.3f} mu1=1 {s.eff_mu1:.1f} % "
                  f"mu2<2.5 {s.eff_mu2:.1f} %", flush=True)
        return rows

    def repeatability(self, ps: PlaceSet, descriptors, n_builds: int, n_queries: int = 10,
                      variants: dict | None = None, all_queries: bool = False) -> dict:
        """Table 8: rebuild each vocabulary with seeds 0..n_builds-1 (Color-Random also redraws its patches) and
        query n_queries fixed, evenly spaced queries. Per query, the share of builds giving its most frequent
        output, averaged over the queries; the output read as the mu1 = 1 outcome (the paper's "highest frequency
        output considering mu1 = 1") and, stricter, as the identity of the top-1 key image. `variants` maps a label
        to parameter changes (the build-option study); `all_queries` also scores every query for Recall@1.
        Builds run seed by seed, so BRIEFROT's unrotated vocabulary is the BRIEF one of the same seed; no tree is
        kept beyond its seed."""
        from loops.vocab import DescriptorName, VisualMemory, brief_angles, repeatability

        pick = np.linspace(0, len(ps.queries) - 1, n_queries).round().astype(int)
        score_idx = np.arange(len(ps.queries)) if all_queries else pick
        truth = [set(ps.truth[ps.queries[i][0]]) for i in range(len(ps.queries))]
        runs = [(desc, label, dict(changes)) for desc in descriptors for label, changes in
                (variants or {"": {}}).items()]
        top1 = {(d, lab): np.full((n_builds, len(score_idx)), -1) for d, lab, _ in runs}
        seconds = {(d, lab): 0.0 for d, lab, _ in runs}
        for r in range(n_builds):
            trees: dict = {}   # this seed's vocabularies, shared between BRIEF and BRIEFROT
            for desc, label, changes in runs:
                t0 = time.perf_counter()
                train_features = changes.get("train_features")
                params = self.params(ps, desc, seed=r, **{k: v for k, v in changes.items() if k != "train_features"})
                redraw = params.descriptor is DescriptorName.COLOR_RANDOM   # its patches depend on the seed
                angles = brief_angles(params)
                per_angle = self.features.keys(ps, params, angles, cache=not redraw)
                tp = params.replace(n_features=train_features) if train_features else params
                train = self.features.keys(ps, tp, angles) if train_features else per_angle
                built = []
                for o, a in enumerate(angles):
                    key = self.vocabs.key(ps.keys_id, tp, o, a)
                    if key not in trees:
                        trees[key] = self.vocabs.tree(ps.keys_id, tp, o, a, train[o], cache=False)[0]
                    built.append(trees[key])
                memory = VisualMemory.from_trees(built, per_angle, ps.key_names, params, angles)
                for j, (_, d, _) in enumerate(self.features.queries(ps, params, score_idx, cache=not redraw)):
                    if d is not None:
                        rk = memory.query_descriptors(d)
                        top1[desc, label][r, j] = rk.keys[0] if len(rk) else -1
                seconds[desc, label] += time.perf_counter() - t0
        out = {}
        cols = np.searchsorted(score_idx, pick)
        for desc, label, _ in runs:
            t = top1[desc, label]
            success = np.array([[int(k) in truth[i] for k, i in zip(row, score_idx)] for row in t])
            s10, t10 = success[:, cols].astype(int), t[:, cols]
            rng = np.random.default_rng(0)
            boot = [repeatability(s10[rng.integers(0, n_builds, n_builds)]) for _ in range(200)]
            name = desc + (f" {label}" if label else "")
            out[name] = {"descriptor": desc, "variant": label, "n_builds": n_builds, "mu1": repeatability(s10),
                         "mu1_se": float(np.std(boot)), "top1": repeatability(t10),
                         "mean_success": float(s10.mean()), "per_query_success": s10.mean(0).tolist(),
                         "seconds": seconds[desc, label]}
            if all_queries:
                r1 = success.mean(1)
                out[name].update({"recall1_mean": float(r1.mean()), "recall1_sd": float(r1.std()),
                                  "mu1_all_queries": repeatability(success.astype(int))})
            print(f"  [repeatability] [{ps.name}] {name}: mu1=1 outcome {100 * out[name]['mu1']:.1f} % "
                  f"(se {100 * out[name]['mu1_se']:.1f}), top-1 key {100 * out[name]['top1']:.1f} % over "
                  f"{n_builds} builds" + (f", R@1 {100 * out[name]['recall1_mean']:.1f} %" if all_queries else "")
                  + f" ({out[name]['seconds']:.0f} s)", flush=True)
        return out

    def timing(self, data: Path, n_keys: int, n_queries: int, descriptors, repeats: int = 3) -> dict:
        """Median query time (extraction + scoring) against an n_keys memory. All memories are built first, then
        timed round-robin (every query through every method in turn), so load from other processes hits them
        alike."""
        from loops.vocab import brief_angles, extract
        from vslam.bench._common import median

        keys, queries, note = timing_images(data, n_keys, n_queries)
        ps = PlaceSet("timing", note, [(f"k{i:04d}", k) for i, k in enumerate(keys)], [], {}, f"timing/{n_keys}",
                      "timing/queries")
        out = {"note": note, "n_keys": len(keys), "n_queries": len(queries), "rows": {}}
        memories = {}
        for desc in descriptors:
            params = self.base.replace(descriptor=desc)
            t0 = time.perf_counter()
            per_angle = self.features.keys(ps, params, brief_angles(params))
            extract_s = time.perf_counter() - t0
            memories[desc], build_s = self.vocabs.memory(ps.keys_id, ps.key_names, params, per_angle,
                                                         brief_angles(params))
            out["rows"][desc] = {"vocabulary_build_s": build_s, "words": [t.n_words for t in memories[desc].trees]}
            print(f"  [timing] {desc} memory: vocabulary {build_s:.0f} s (key extraction {extract_s:.0f} s)",
                  flush=True)
        if self.pydbow_cfg:
            params = self.base.replace(descriptor="orb")
            distinct = max(1, n_keys // 4)
            t0 = time.perf_counter()
            descs = self.features.keys(ps, params, (0.0,))[0][:distinct]
            memories["pydbow-orb"] = PydbowMemory(descs, ps.key_names[:distinct], params, self.pydbow_cfg["k"],
                                                  self.pydbow_cfg["depth"], self.pydbow_cfg["max_train"],
                                                  replicate=-(-n_keys // distinct))
            out["rows"]["pydbow-orb"] = {"vocabulary_build_s": time.perf_counter() - t0,
                                         "words": [memories["pydbow-orb"].n_words],
                                         "entries": len(memories["pydbow-orb"])}
            print(f"  [timing] pydbow memory ({len(memories['pydbow-orb'])} entries from {distinct} distinct key "
                  f"images): {out['rows']['pydbow-orb']['vocabulary_build_s']:.0f} s", flush=True)
        times = {name: {"total": [], "extract": [], "score": []} for name in memories}
        for rep in range(repeats):
            for q in queries:
                for name, memory in memories.items():
                    if name.startswith("pydbow") and rep > 0:
                        continue  # one pass is plenty at its speed
                    t0 = time.perf_counter()
                    d = extract(q, memory.params)[0]
                    t1 = time.perf_counter()
                    memory.query_descriptors(d)
                    t2 = time.perf_counter()
                    times[name]["extract"].append(t1 - t0)
                    times[name]["score"].append(t2 - t1)
                    times[name]["total"].append(t2 - t0)
        for name, t in times.items():
            out["rows"][name].update({"query_ms": 1e3 * median(t["total"]), "extract_ms": 1e3 * median(t["extract"]),
                                      "score_ms": 1e3 * median(t["score"])})
            print(f"  [timing] {name}: {out['rows'][name]['query_ms']:.1f} ms/query (extract "
                  f"{out['rows'][name]['extract_ms']:.1f}, score {out['rows'][name]['score_ms']:.2f})", flush=True)
        return out


def key_similarity_spread(memory) -> dict:
    """How mu2's weights z_l(I*_k) spread over the other key images: per key image, how many others have z > 0
    and which share of the weight sum_l z_l they get (0 = mu2 is mu1)."""
    n = len(memory)
    z = np.array([memory.key_similarity(k) for k in range(n)])
    others = z - np.diag(np.diag(z))
    return {"z_other_keys": float((others > 0).sum(1).mean()),
            "z_other_weight": float((others.sum(1) / z.sum(1)).mean())}


def spread_table(report_sets: dict) -> str:
    from vslam.bench._common import format_table

    names = list(report_sets)
    labels = []
    for v in report_sets.values():
        labels += [d for d in v["details"] if d not in labels and "z_other_keys" in v["details"][d]]
    rows = []
    for d in labels:
        cells = []
        for name in names:
            x = report_sets[name]["details"].get(d)
            cells.append(f"{x['z_other_keys']:.1f} / {100 * x['z_other_weight']:.0f} %" if x else "-")
        rows.append((d, *cells))
    return format_table(("Descriptor", *names), rows)


def shared_words(bench: "Bench", ps: PlaceSet, desc: str = "brief") -> dict:
    """How strong the retrieval signal is: per query, the words shared with its best-scoring true key image and
    with the best-scoring wrong one (single-vocabulary descriptor, seed 0); medians over the queries."""
    params = bench.params(ps, desc)
    memory, _ = bench.memory(ps, params)
    db, tree = memory.databases[0], memory.trees[0]
    true_w, wrong_w = [], []
    for name, d, _ in bench.features.queries(ps, params):
        if d is None:
            continue
        s = db.score(tree.transform(d), 1)
        is_true = np.isin(s.keys, ps.truth[name])
        true_w.append(int(s.shared[is_true][0]) if is_true.any() else 0)
        wrong_w.append(int(s.shared[~is_true][0]) if (~is_true).any() else 0)
    return {"descriptor": desc, "best_true_key_words": float(np.median(true_w)),
            "best_wrong_key_words": float(np.median(wrong_w)),
            "words_per_query": float(np.median([len(d) for _, d, _ in bench.features.queries(ps, params)
                                                if d is not None]))}


def timing_images(data: Path, n_keys: int, n_queries: int) -> tuple[list, list, str]:
    """A memory of n_keys real-image-derived 640x480 frames (corridor upscaled, KITTI and pairs cropped to 4:3)
    in variants (as is, mirrored, zoomed 1.2x, rotated 4 deg) and n_queries held-out variants (rotated -3 deg,
    zoomed 1.1x)."""
    import cv2

    def to_vga(img):
        h, w = img.shape[:2]
        if w * 3 > h * 4:  # too wide: centre crop to 4:3
            cw = h * 4 // 3
            img = img[:, (w - cw) // 2:(w - cw) // 2 + cw]
        elif w * 3 < h * 4:
            ch = w * 3 // 4
            img = img[(h - ch) // 2:(h - ch) // 2 + ch]
        return cv2.resize(img, (640, 480), interpolation=cv2.INTER_LINEAR)

    def zoom(img, f):
        h, w = img.shape[:2]
        ch, cw = int(h / f), int(w / f)
        return cv2.resize(img[(h - ch) // 2:(h - ch) // 2 + ch, (w - cw) // 2:(w - cw) // 2 + cw], (w, h))

    def rot(img, a):
        return zoom(rotate_with_mask(img, a)[0], 1.25)

    paths = sorted((data / "places" / "corridor").glob("*/*.jpg"))
    paths += sorted((data / "places" / "kitti_snippets").glob("KITTI_sequence_*/image_l/*.png"))
    paths += sorted((data / "pairs" / "images").glob("*.png"))
    pool = []
    for p in paths:
        img = to_vga(_imread(p))
        pool.append(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img)
    variants = [lambda im: im, lambda im: cv2.flip(im, 1), lambda im: zoom(im, 1.2), lambda im: rot(im, 4.0)]
    keys = [variants[(i // len(pool)) % len(variants)](pool[i % len(pool)]) for i in range(n_keys)]
    step = max(1, len(pool) // n_queries)
    queries = [zoom(rot(pool[(j * step) % len(pool)], -3.0), 1.1) for j in range(n_queries)]
    note = (f"{n_keys} key images at 640x480 from {len(pool)} real frames (corridor x4 upscaled, KITTI and pairs "
            "cropped to 4:3) in variants (as is, mirrored, zoomed, rotated); queries = rotated+zoomed variants")
    return keys, queries, note


# ---- output ------------------------------------------------------------------------------------------------------
def summary_dict(s) -> dict:
    return {"n_tests": s.n_tests, "correct_mu1": s.correct_mu1, "effectiveness_mu1_pct": s.eff_mu1,
            "correct_mu2": s.correct_mu2, "effectiveness_mu2_pct": s.eff_mu2, "recall_at_1": s.recall1,
            "recall_at_5": s.recall5, "average_precision": s.average_precision, "median_ms": s.median_ms}


def plot_sweep(path: Path, rows, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from odometry.shared.atomic_io import atomic_path

    th = [r[0] for r in rows]
    fig, ax = plt.subplots(figsize=(5, 3.2), dpi=100)
    ax.plot(th, [r[1].eff_mu1 for r in rows], "o-", label="mu1 = 1")
    ax.plot(th, [r[1].eff_mu2 for r in rows], "s--", label="mu2 < 2.5")
    ax.set_xlabel("BRIEFROT theta (deg; 0 = BRIEF)")
    ax.set_ylabel("effectiveness (%)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def repeat_table(values: dict) -> str:
    from loops.vocab import DescriptorName
    from vslam.bench._common import format_table

    rows = []
    for set_name, rep in values.items():
        for name, v in rep.items():
            rows.append((set_name, DescriptorName(v["descriptor"]).label + (f" {v['variant']}" if v["variant"] else ""),
                         v["n_builds"], f"{100 * v['mu1']:.1f} ± {100 * v['mu1_se']:.1f}", round(100 * v["top1"], 1),
                         round(100 * v["mean_success"], 1))
                        + ((round(100 * v["recall1_mean"], 1), round(100 * v["recall1_sd"], 1),
                            round(100 * v["mu1_all_queries"], 1)) if "recall1_mean" in v else ()))
    headers = ("Set", "Descriptor", "builds", "Repeatability, mu1=1 outcome (%) ± se", "Repeatability, top-1 key (%)",
               "mean mu1=1 rate (%)")
    if rows and len(rows[0]) > len(headers):
        headers += ("Recall@1 mean over builds (%)", "Recall@1 sd (%)", "Repeatability, all queries (%)")
    return format_table(headers, rows)


def run_repeat_study(args, bench: Bench, data: Path, out: Path) -> int:
    """Gap study: do Lloyd iterations, k-means++ restarts or more descriptors make builds steadier?"""
    from odometry.shared.atomic_io import atomic_write_text
    from vslam.bench._common import write_json

    n_builds = args.builds or (10 if args.quick else 30)
    variants = {"baseline": {}, "iters=30": {"kmeans_iters": 30}, "restarts=3": {"kmeans_restarts": 3},
                "features=1000": {"n_features": 1000}, "train on 1500/img": {"train_features": 1500}}
    values = {}
    for set_name in ("corridor", "kitti"):
        ps = load_set(set_name, data, args.quick)
        print(f"== build-option study on {set_name}: {n_builds} builds per option", flush=True)
        values[set_name] = bench.repeatability(ps, [d for d in ("brief", "briefrot") if d in args.descriptors],
                                               n_builds, variants=variants, all_queries=True)
    table = repeat_table(values)
    text = (f"### Repeatability and Recall@1 under vocabulary-build options ({n_builds} builds each)\n\n"
            f"`{' '.join(['vslam'] + sys.argv[1:])}` ({datetime.date.today().isoformat()})\n\n{table}\n")
    print("\n" + text)
    write_json(out / "repeat_study.json", {"n_builds": n_builds, "variants": variants, "values": values})
    atomic_write_text(out / "repeat_study.md", text)
    return 0


def run(args: argparse.Namespace) -> int:
    from loops.vocab import DescriptorName, preset
    from odometry.shared.atomic_io import atomic_write_text
    from vslam.bench._common import format_table, write_json
    from vslam.cli.cmd_localize import format_paper_table, save_pr_plot
    from vslam.paths import shared_data_dir

    data = shared_data_dir(required=True)
    out = Path(args.out)
    quick = args.quick
    base = preset(args.preset)
    pydbow_cfg = None
    pydbow_note = ""
    if not args.no_pydbow:
        try:
            import dbow  # noqa: F401  (the `pydbow` distribution installs the module `dbow`)

            pydbow_cfg = {"k": 10, "depth": 2 if quick else 3, "max_train": 3000 if quick else 5000,
                          "features": ["orb"] if quick else ["orb", "brief"]}
        except ImportError:
            pydbow_note = "pydbow is not installed (pip install -e '.[bench]'): comparison skipped"
            print(pydbow_note)
    bench = Bench(base, pydbow_cfg)
    if args.repeat_study:
        return run_repeat_study(args, bench, data, out)
    command = " ".join(["vslam"] + sys.argv[1:]) if Path(sys.argv[0]).name != "pytest" else "vslam bench localize"
    report: dict = {"quick": quick, "preset": base.to_dict(), "pydbow": pydbow_cfg, "pydbow_note": pydbow_note,
                    "command": command, "date": datetime.date.today().isoformat(), "sets": {}, "stage_seconds": {}}
    t_start = time.perf_counter()
    md: list[str] = []
    loaded: dict[str, PlaceSet] = {}

    def get_set(name: str) -> PlaceSet:
        if name not in loaded:
            loaded[name] = load_set(name, data, quick)
            write_truth(out / "truth" / f"{name}.csv", loaded[name])
        return loaded[name]

    def stage(name: str, t0: float) -> None:
        report["stage_seconds"][name] = time.perf_counter() - t0
        print(f"== {name} stage: {report['stage_seconds'][name] / 60:.1f} min", flush=True)

    if "sets" not in args.skip:
        t0 = time.perf_counter()
        for name in args.sets:
            ps = get_set(name)
            print(f"== {name}: {len(ps.keys)} key images, {len(ps.queries)} queries", flush=True)
            res = bench.run_set(ps, args.descriptors)
            table = format_paper_table(res.rows)
            # only colour vocabularies on grayscale sets are skipped: one line for them
            skipped = "".join(f"\n{', '.join(res.skipped)}: skipped ({why.replace(d, '/'.join(res.skipped))})"
                              for d, why in list(res.skipped.items())[:1])
            md.append(f"#### {name}\n\n{ps.note}.\n\n{table}\n{skipped}\n")
            save_pr_plot(out / f"pr_{name}.png", res.curves, f"{name}: top-1 precision-recall")
            report["sets"][name] = {"note": ps.note, "n_keys": len(ps.keys), "n_queries": len(ps.queries),
                                    "rows": {label: summary_dict(s) for label, s in res.rows},
                                    "skipped": res.skipped, "details": res.extra}
        md.append("#### mu2's weights: other key images with z > 0 per key / their share of the weights\n\n"
                  "z_l(I*_k) = similarity of key l to the true key k in the memory (1 for k, 0 below "
                  "min_shared words); a share of 0 % makes mu2 = mu1.\n\n" + spread_table(report["sets"]) + "\n")
        stage("sets", t0)
    if "sweep" not in args.skip:
        t0 = time.perf_counter()
        ps = get_set("corridor-rot")
        thetas = [0, 8, 16] if quick else [0, 4, 8, 12, 16, 20, 24]
        print("== BRIEFROT theta sweep on corridor-rot", flush=True)
        rows = bench.theta_sweep(ps, thetas)
        table = format_table(("theta (deg)", "Effectiveness mu1 (%)", "Effectiveness mu2 (%)", "Recall@1",
                              "Recall@5", "AP", "top-1 vocabulary 0/+theta/-theta"),
                             [(th, round(s.eff_mu1, 2), round(s.eff_mu2, 2), round(s.recall1, 3), round(s.recall5, 3),
                               round(s.average_precision, 3), "/".join(map(str, w))) for th, s, w in rows])
        md.append(f"#### BRIEFROT theta sweep (corridor-rot; theta 0 = BRIEF)\n\n{table}\n")
        plot_sweep(out / "theta_sweep.png", rows, "BRIEFROT on corridor queries rotated 10-30 deg")
        report["theta_sweep"] = [{"theta": th, **summary_dict(s), "top1_vocabulary_counts": w} for th, s, w in rows]
        stage("sweep", t0)
    if "repeat" not in args.skip:
        t0 = time.perf_counter()
        n_builds = args.builds or (10 if quick else 30)
        print(f"== repeatability: {n_builds} vocabulary builds per descriptor", flush=True)
        rep_desc = [d for d in REPEAT_DESCRIPTORS if d in args.descriptors]
        report["repeatability"] = {"n_builds": n_builds, "n_queries": 10, "values": {}}
        for set_name in REPEAT_SETS:
            ps = get_set(set_name)
            descs = [d for d in rep_desc if not (ps.grayscale and DescriptorName(d).is_color)]
            report["repeatability"]["values"][set_name] = bench.repeatability(ps, descs, n_builds)
            report["repeatability"].setdefault("signal", {})[set_name] = shared_words(bench, ps)
        signal = "; ".join(f"{name} {v['best_true_key_words']:g} vs {v['best_wrong_key_words']:g} of "
                           f"{v['words_per_query']:g}" for name, v in report["repeatability"]["signal"].items())
        md.append(f"#### Repeatability of visual vocabularies (Table 8): {n_builds} builds (seeds 0..{n_builds - 1}), "
                  f"10 queries per set\n\n{repeat_table(report['repeatability']['values'])}\n\n"
                  f"Retrieval signal (BRIEF, seed 0; median over the queries of the words shared with the best true "
                  f"key vs the best wrong key, of the query's descriptors): {signal}.\n")
        stage("repeatability", t0)
    if "timing" not in args.skip:
        t0 = time.perf_counter()
        n_keys = args.timing_images or (300 if quick else 1000)
        print(f"== query time against a {n_keys}-image 640x480 memory", flush=True)
        tim_desc = [d for d in ("brief", "briefrot", "orb") if d in args.descriptors]
        tim = bench.timing(data, n_keys, 20 if quick else 40, tim_desc)
        rows = []
        ref = tim["rows"].get("pydbow-orb", {}).get("query_ms")
        for d, r in tim["rows"].items():
            speed = f"{ref / r['query_ms']:.1f}x" if ref else "-"
            rows.append((d, r["query_ms"], r.get("extract_ms", float("nan")), r.get("score_ms", float("nan")),
                         "/".join(map(str, r["words"])), round(r["vocabulary_build_s"], 1), speed))
        table = format_table(("Descriptor", "Median query (ms)", "extraction (ms)", "scoring (ms)", "words",
                              "vocabulary build (s)", "speed-up vs pydbow"), rows)
        md.append(f"#### Query time, {tim['n_keys']}-image memory at 640x480 (median over {tim['n_queries']} "
                  f"queries x 3; pydbow x 1)\n\n{tim['note']}.\n\n{table}\n")
        report["timing"] = tim
        stage("timing", t0)
    report["elapsed_s"] = time.perf_counter() - t_start
    head = (f"`{command}` on {report['date']}: {report['elapsed_s'] / 60:.1f} min ("
            + ", ".join(f"{k} {v / 60:.1f}" for k, v in report["stage_seconds"].items()) + " min)\n")
    text = head + "\n" + "\n".join(md)
    print("\n" + text)
    write_json(out / "localize.json", report)
    atomic_write_text(out / "localize.md", text)
    print(f"wrote {out / 'localize.json'}, {out / 'localize.md'} and plots in {out}")
    return 0
