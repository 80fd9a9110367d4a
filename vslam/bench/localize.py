"""`vslam bench localize`: visual-memory localisation on real image sets, in the paper's table layout.

Sets (from ../shared/data): corridor (reference traverse = memory, second traverse = queries), corridor-rot (the
same queries rotated by 10-30 degrees, alternating sign, seeded), kitti (two KITTI snippets, every 3rd frame a key
image), pairs (the 48 labelled pairs: one key image per scene). Every descriptor runs on every set, beside the
`pydbow` package on the same images and the same (ORB / BRIEF) descriptors. Then: the BRIEFROT theta sweep (Fig. 11),
repeatability over vocabulary rebuilds (Table 8) and the query time against a 1000-image 640x480 memory.
Prints markdown tables, writes JSON and PNG plots into --out.
"""
from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

NAME = "localize"
HELP = "visual-memory localisation: paper tables on real sets, pydbow comparison, repeatability, query time"
ALL_DESCRIPTORS = ("brief", "briefrot", "orb", "surf", "color-random", "color-whole", "color-half")
SETS = ("corridor", "corridor-rot", "kitti", "pairs")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="smaller run (~ a few minutes): fewer queries, builds, angles")
    p.add_argument("--out", default="bench-out/localize", help="output folder for JSON, CSV truth files and plots")
    p.add_argument("--sets", nargs="+", choices=SETS, default=list(SETS))
    p.add_argument("--descriptors", nargs="+", choices=ALL_DESCRIPTORS, default=list(ALL_DESCRIPTORS))
    p.add_argument("--preset", default="paper", help="vocabulary preset (paper: k=8, L=8 as in the paper; default; fast)")
    p.add_argument("--no-pydbow", action="store_true", help="skip the pydbow comparison")
    p.add_argument("--skip", nargs="*", default=[], choices=("sets", "sweep", "repeat", "timing"),
                   help="parts to skip")
    p.add_argument("--timing-images", type=int, help="memory size for the query-time target (default 1000)")


# ---- data sets ---------------------------------------------------------------------------------------------------
@dataclass
class PlaceSet:
    name: str
    note: str
    keys: list  # [(name, image)]
    queries: list  # [(name, image, mask or None)]
    truth: dict  # query name -> [key indices]
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
    return PlaceSet("corridor-rot" if rotated else "corridor", note, keys, queries, truth, min_side=480)


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
    return PlaceSet("kitti", note, keys, queries, truth, grayscale=True)


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
    return PlaceSet("pairs", note, keys, queries, truth, grayscale=True)


def load_set(name: str, data: Path, quick: bool) -> PlaceSet:
    if name == "corridor":
        return corridor_set(data, stride=3 if quick else 1)
    if name == "corridor-rot":
        return corridor_set(data, rotated=True, stride=3 if quick else 1)
    if name == "kitti":
        return kitti_set(data)
    return pairs_set(data)


def write_truth(path: Path, ps: PlaceSet) -> None:
    from odometry.atomic_io import atomic_write_text

    rows = ["query,key"] + [f"{q},{ps.keys[k][0]}" for q, ks in ps.truth.items() for k in ks]
    atomic_write_text(path, "\n".join(rows) + "\n")


# ---- pydbow adapter ----------------------------------------------------------------------------------------------
class PydbowMemory:
    """The `pydbow` package (PyPI, pure-Python DBoW) behind the VisualMemory query interface, fed with our
    descriptors. Its Vocabulary() runs ORB itself, so the tree is built with its own initialize_tree() on our
    descriptors instead; its k-means draws from numpy's global generator, which is seeded here."""

    def __init__(self, key_descs: list[np.ndarray], key_names: list[str], params, k: int, depth: int,
                 max_train: int, seed: int = 0):
        import dbow

        self.dbow, self.params, self.key_names = dbow, params, list(key_names)
        train = np.concatenate(key_descs)
        rng = np.random.default_rng(seed)
        if len(train) > max_train:
            train = train[np.sort(rng.choice(len(train), max_train, replace=False))]
        np.random.seed(seed)
        voc = dbow.Vocabulary.__new__(dbow.Vocabulary)
        voc.root_node = dbow.Node([dbow.ORB.from_cv_descriptor(x) for x in train])
        voc.words = [dbow.Word.from_node(n) for n in dbow.dbow.initialize_tree(voc.root_node, k, depth)]
        for w in voc.words:
            w.update_weight(len(key_descs))
        self.db = dbow.Database(voc)
        for d in key_descs:
            self.db.add(self._convert(d))
        self.n_words = len(voc.words)

    def _convert(self, descs: np.ndarray) -> list:
        return [self.dbow.ORB.from_cv_descriptor(x) for x in descs]

    def __len__(self) -> int:
        return len(self.key_names)

    def query(self, image: np.ndarray, mask=None, name: str = "query"):
        from loops.vocab import extract

        return self.query_descriptors(extract(image, self.params, mask, name=name)[0])

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


def key_descriptors(ps: PlaceSet, params) -> tuple[tuple, list]:
    """Pattern angles and per_angle[o][i] = descriptors of key image i (extracted once, reused for mu2)."""
    from loops.vocab import brief_angles, extract

    angles = brief_angles(params)
    per_key = [extract(im, params, angles=angles, name=n) for n, im in ps.keys]
    return angles, [[d[o] for d in per_key] for o in range(len(angles))]


def run_set(ps: PlaceSet, descriptors, base, pydbow_cfg) -> SetResult:
    from loops.vocab import GrayscaleImageError, VisualMemory, evaluate

    res = SetResult()
    for desc in descriptors:
        params = base.replace(descriptor=desc, min_image_side=ps.min_side)
        t0 = time.perf_counter()
        try:
            angles, per_angle = key_descriptors(ps, params)
        except GrayscaleImageError as exc:
            res.skipped[desc] = str(exc)
            continue
        memory = VisualMemory.from_descriptors(per_angle, ps.key_names, params, angles)
        build_s = time.perf_counter() - t0
        ev = evaluate(memory, iter(ps.queries), ps.truth, key_descriptors=lambda i: per_angle[0][i])
        s = ev.summary()
        res.rows.append((params.descriptor.label, s))
        res.curves[params.descriptor.label] = ev.pr()
        res.extra[desc] = {"build_s": build_s, "words": [t.n_words for t in memory.trees],
                           "top1_vocabulary_counts": ev.winner_counts(len(memory.angles)).tolist(),
                           "pattern_angles": list(memory.angles)}
        print(f"  [{ps.name}] {params.descriptor.label}: R@1 {s.recall1:.3f}, mu1=1 {s.eff_mu1:.1f} %, "
              f"{s.median_ms:.1f} ms/query, build {build_s:.1f} s", flush=True)
    if pydbow_cfg:
        for feat in pydbow_cfg["features"]:
            params = base.replace(descriptor=feat, min_image_side=ps.min_side)
            from loops.vocab import extract

            t0 = time.perf_counter()
            key_descs = [extract(im, params, name=n)[0] for n, im in ps.keys]
            pm = PydbowMemory(key_descs, ps.key_names, params, pydbow_cfg["k"], pydbow_cfg["depth"],
                              pydbow_cfg["max_train"])
            build_s = time.perf_counter() - t0
            ev = evaluate(pm, iter(ps.queries), ps.truth, key_descriptors=lambda i: key_descs[i])
            s = ev.summary()
            label = f"pydbow ({params.descriptor.label})"
            res.rows.append((label, s))
            res.curves[label] = ev.pr()
            res.extra[f"pydbow-{feat}"] = {"build_s": build_s, "words": [pm.n_words]}
            print(f"  [{ps.name}] {label}: R@1 {s.recall1:.3f}, {s.median_ms:.1f} ms/query, build {build_s:.1f} s",
                  flush=True)
    return res


def theta_sweep(ps: PlaceSet, thetas, base) -> list[tuple]:
    """Fig. 11: BRIEFROT effectiveness against the rotation angle theta (theta = 0 degenerates to three copies of
    BRIEF, which is why the BRIEF row is reported beside it)."""
    from loops.vocab import VisualMemory, evaluate

    rows = []
    for th in thetas:
        desc = "brief" if th == 0 else "briefrot"
        params = base.replace(descriptor=desc, rot_theta_deg=float(th), min_image_side=ps.min_side)
        angles, per_angle = key_descriptors(ps, params)
        memory = VisualMemory.from_descriptors(per_angle, ps.key_names, params, angles)
        ev = evaluate(memory, iter(ps.queries), ps.truth, key_descriptors=lambda i: per_angle[0][i])
        s = ev.summary()
        rows.append((float(th), s, ev.winner_counts(len(memory.angles)).tolist()))
        print(f"  [theta sweep] theta {th:g}: R@1 {s.recall1:.3f} mu1=1 {s.eff_mu1:.1f} % mu2<2.5 {s.eff_mu2:.1f} %",
              flush=True)
    return rows


def repeatability_runs(ps: PlaceSet, descriptors, base, n_builds: int, n_queries: int) -> dict:
    """Table 8: rebuild each vocabulary with seeds 0..n_builds-1 (colour-random also redraws its patches) and, for
    n_queries fixed queries, measure the share of builds giving the most frequent output, averaged over queries.
    Two readings of "output": whether mu1 = 1 (the paper: "highest frequency output considering mu1 = 1") and,
    stricter, the identity of the top-1 key image."""
    from loops.vocab import VisualMemory, extract, repeatability

    pick = np.linspace(0, len(ps.queries) - 1, n_queries).round().astype(int)
    out = {}
    for desc in descriptors:
        top1 = np.full((n_builds, len(pick)), -1)
        cache = None
        for r in range(n_builds):
            params = base.replace(descriptor=desc, seed=r, min_image_side=ps.min_side)
            if cache is None or desc == "color-random":
                _, per_angle = key_descriptors(ps, params)
                qd = [extract(ps.queries[i][1], params, ps.queries[i][2])[0] for i in pick]
                cache = (per_angle, qd)
            per_angle, qd = cache
            memory = VisualMemory.from_descriptors(per_angle, ps.key_names, params)
            for j, d in enumerate(qd):
                rk = memory.query_descriptors(d)
                top1[r, j] = rk.keys[0] if len(rk) else -1
        success = np.array([[int(k) in ps.truth[ps.queries[i][0]] for k, i in zip(row, pick)] for row in top1])
        out[desc] = {"mu1": repeatability(success.astype(int)), "top1": repeatability(top1),
                     "mean_success": float(success.mean())}
        print(f"  [repeatability] [{ps.name}] {desc}: mu1=1 outcome {100 * out[desc]['mu1']:.1f} %, top-1 key "
              f"{100 * out[desc]['top1']:.1f} % over {n_builds} builds", flush=True)
    return out


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
    pool = [cv2.cvtColor(to_vga(_imread(p)), cv2.COLOR_GRAY2BGR) if _imread(p).ndim == 2 else to_vga(_imread(p))
            for p in paths]
    variants = [lambda im: im, lambda im: cv2.flip(im, 1), lambda im: zoom(im, 1.2), lambda im: rot(im, 4.0)]
    keys = [variants[(i // len(pool)) % len(variants)](pool[i % len(pool)]) for i in range(n_keys)]
    step = max(1, len(pool) // n_queries)
    queries = [zoom(rot(pool[(j * step) % len(pool)], -3.0), 1.1) for j in range(n_queries)]
    note = (f"{n_keys} key images at 640x480 from {len(pool)} real frames (corridor x4 upscaled, KITTI and pairs "
            "cropped to 4:3) in variants (as is, mirrored, zoomed, rotated); queries = rotated+zoomed variants")
    return keys, queries, note


def timing_runs(data: Path, n_keys: int, n_queries: int, base, descriptors, pydbow_cfg, repeats: int = 3) -> dict:
    """Median query time (extraction + scoring) against an n_keys memory. All memories are built first, then timed
    round-robin (every query through every method in turn), so load from other processes hits them alike."""
    from loops.vocab import VisualMemory, extract
    from vslam.bench._common import median

    keys, queries, note = timing_images(data, n_keys, n_queries)
    names = [f"k{i:04d}" for i in range(len(keys))]
    out = {"note": note, "n_keys": len(keys), "n_queries": len(queries), "rows": {}}
    memories = {}
    for desc in descriptors:
        params = base.replace(descriptor=desc)
        t0 = time.perf_counter()
        memories[desc] = VisualMemory.build(keys, names, params)
        out["rows"][desc] = {"build_s": time.perf_counter() - t0, "words": [t.n_words for t in memories[desc].trees]}
        print(f"  [timing] built {desc} memory in {out['rows'][desc]['build_s']:.0f} s", flush=True)
    if pydbow_cfg:
        params = base.replace(descriptor="orb")
        t0 = time.perf_counter()
        memories["pydbow-orb"] = PydbowMemory([extract(k, params)[0] for k in keys], names, params, pydbow_cfg["k"],
                                              pydbow_cfg["depth"], pydbow_cfg["max_train"])
        out["rows"]["pydbow-orb"] = {"build_s": time.perf_counter() - t0, "words": [memories["pydbow-orb"].n_words]}
        print(f"  [timing] built pydbow memory in {out['rows']['pydbow-orb']['build_s']:.0f} s", flush=True)
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


# ---- output ------------------------------------------------------------------------------------------------------
def summary_dict(s) -> dict:
    return {"n_tests": s.n_tests, "correct_mu1": s.correct_mu1, "effectiveness_mu1_pct": s.eff_mu1,
            "correct_mu2": s.correct_mu2, "effectiveness_mu2_pct": s.eff_mu2, "recall_at_1": s.recall1,
            "recall_at_5": s.recall5, "average_precision": s.average_precision, "median_ms": s.median_ms}


def plot_sweep(path: Path, rows, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from odometry.atomic_io import atomic_path

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


def run(args: argparse.Namespace) -> int:
    from loops.vocab import preset
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
    report: dict = {"quick": quick, "preset": base.to_dict(), "pydbow": pydbow_cfg, "pydbow_note": pydbow_note,
                    "sets": {}}
    t_start = time.perf_counter()
    md: list[str] = []
    loaded: dict[str, PlaceSet] = {}

    def get_set(name: str) -> PlaceSet:
        if name not in loaded:
            loaded[name] = load_set(name, data, quick)
            write_truth(out / "truth" / f"{name}.csv", loaded[name])
        return loaded[name]

    if "sets" not in args.skip:
        for name in args.sets:
            ps = get_set(name)
            print(f"== {name}: {len(ps.keys)} key images, {len(ps.queries)} queries", flush=True)
            res = run_set(ps, args.descriptors, base, pydbow_cfg)
            table = format_paper_table(res.rows)
            skipped = "".join(f"\n- {d}: skipped ({why})" for d, why in res.skipped.items())
            md.append(f"### {name}\n\n{ps.note}.\n\n{table}\n{skipped}\n")
            save_pr_plot(out / f"pr_{name}.png", res.curves, f"{name}: top-1 precision-recall")
            report["sets"][name] = {"note": ps.note, "n_keys": len(ps.keys), "n_queries": len(ps.queries),
                                    "rows": {label: summary_dict(s) for label, s in res.rows},
                                    "skipped": res.skipped, "details": res.extra}
    if "sweep" not in args.skip:
        ps = get_set("corridor-rot")
        thetas = [0, 8, 16] if quick else [0, 4, 8, 12, 16, 20, 24]
        print("== BRIEFROT theta sweep on corridor-rot", flush=True)
        rows = theta_sweep(ps, thetas, base)
        table = format_table(("theta (deg)", "Effectiveness mu1 (%)", "Effectiveness mu2 (%)", "Recall@1",
                              "Recall@5", "top-1 vocabulary 0/+theta/-theta"),
                             [(th, round(s.eff_mu1, 2), round(s.eff_mu2, 2), round(s.recall1, 3), round(s.recall5, 3),
                               "/".join(map(str, w))) for th, s, w in rows])
        md.append(f"### BRIEFROT theta sweep (corridor-rot; theta 0 = BRIEF)\n\n{table}\n")
        plot_sweep(out / "theta_sweep.png", rows, "BRIEFROT on corridor queries rotated 10-30 deg")
        report["theta_sweep"] = [{"theta": th, **summary_dict(s), "top1_vocabulary_counts": w} for th, s, w in rows]
    if "repeat" not in args.skip:
        from loops.vocab import DescriptorName

        n_builds = 3 if quick else 6
        print(f"== repeatability: {n_builds} vocabulary builds per descriptor", flush=True)
        rep_desc = [d for d in ("brief", "briefrot", "color-random", "orb", "surf") if d in args.descriptors]
        report["repeatability"] = {"n_builds": n_builds, "n_queries": 10, "values": {}}
        rows = []
        for set_name in ("corridor", "kitti"):
            ps = get_set(set_name)
            descs = [d for d in rep_desc if not (ps.grayscale and DescriptorName(d).is_color)]
            rep = repeatability_runs(ps, descs, base, n_builds, 10)
            report["repeatability"]["values"][set_name] = rep
            rows += [(set_name, DescriptorName(d).label, round(100 * v["mu1"], 1), round(100 * v["top1"], 1),
                      round(100 * v["mean_success"], 1)) for d, v in rep.items()]
        table = format_table(("Set", "Descriptor", "Repeatability, mu1=1 outcome (%)", "Repeatability, top-1 key (%)",
                              "mean mu1=1 rate (%)"), rows)
        md.append(f"### Repeatability of visual vocabularies (Table 8): {n_builds} builds (seeds 0..{n_builds - 1}), "
                  f"10 queries per set\n\n{table}\n")
    if "timing" not in args.skip:
        n_keys = args.timing_images or (300 if quick else 1000)
        print(f"== query time against a {n_keys}-image 640x480 memory", flush=True)
        tim_desc = [d for d in ("brief", "briefrot", "orb") if d in args.descriptors]
        tim = timing_runs(data, n_keys, 20 if quick else 40, base, tim_desc, pydbow_cfg)
        rows = []
        ref = tim["rows"].get("pydbow-orb", {}).get("query_ms")
        for d, r in tim["rows"].items():
            speed = f"{ref / r['query_ms']:.1f}x" if ref else "-"
            rows.append((d, r["query_ms"], r.get("extract_ms", float("nan")), r.get("score_ms", float("nan")),
                         "/".join(map(str, r["words"])), round(r["build_s"], 1), speed))
        table = format_table(("Descriptor", "Median query (ms)", "extraction (ms)", "scoring (ms)", "words",
                              "build (s)", "speed-up vs pydbow"), rows)
        md.append(f"### Query time, {tim['n_keys']}-image memory at 640x480 (median over {tim['n_queries']} queries"
                  f" x 3)\n\n{tim['note']}.\n\n{table}\n")
        report["timing"] = tim
    text = "\n".join(md)
    print("\n" + text)
    report["elapsed_s"] = time.perf_counter() - t_start
    write_json(out / "localize.json", report)
    from odometry.atomic_io import atomic_write_text

    atomic_write_text(out / "localize.md", text)
    print(f"wrote {out / 'localize.json'}, {out / 'localize.md'} and plots in {out}  "
          f"({report['elapsed_s'] / 60:.1f} min)")
    return 0
