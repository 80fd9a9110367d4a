"""`vslam localize`: kidnapped-robot localisation in a visual memory with a vocabulary-tree bag of words.

    vslam localize build MEMORY_DIR [--descriptor briefrot] [--out memory.vmem]
    vslam localize query memory.vmem IMAGE [IMAGE ...] [--top 5]
    vslam localize eval MEMORY_DIR QUERIES_DIR --truth TRUTH.csv --descriptor NAME --out DIR

MEMORY_DIR / QUERIES_DIR are image folders or sequence directories (frames.csv). Images are named by their path
relative to that folder (the file name for a flat folder); TRUTH.csv has the header `query,key` with such names,
several rows per query allowed.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
from pathlib import Path

from vslam.errors import VslamError

NAME = "localize"
HELP = "visual-memory localisation (vocabulary-tree bag of words): build, query, eval"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm")
DESCRIPTORS = ("brief", "briefrot", "orb", "surf", "color-random", "color-whole", "color-half")
DISTANCES = ("chi2", "dot", "bhattacharyya", "l1", "l2")


# ---- shared with vslam.bench.localize ---------------------------------------------------------------------------
def list_images(folder: str | Path) -> list[tuple[str, Path]]:
    """(name, path) of the images of an image folder, or of a sequence directory's frames.csv, in order."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: not a directory")
    if (folder / "frames.csv").is_file():
        from vslam.io import read_sequence_dir

        seq = read_sequence_dir(folder, require_camera=False)   # validated: header, timestamps, images exist
        out = [(rel, folder / rel) for rel in seq.images.relpaths]
    else:
        out = [(str(p.relative_to(folder)), p) for p in sorted(folder.rglob("*"))
               if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()]
    if not out:
        raise VslamError(f"{folder}: no images found (expected image files or a frames.csv)")
    return out


def read_image(path: Path):
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise OSError(f"{path}: cannot read image")
    if img.dtype != "uint8":
        img = cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    if img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


def read_truth(path: str | Path, query_names: list[str], key_names: list[str]) -> dict[str, list[int]]:
    """TRUTH.csv (header query,key) -> {query name: [key indices]}. Names match a full relative name or a file
    name; unknown names are errors naming the line."""
    path = Path(path)
    q_index = _name_index(query_names)
    k_index = _name_index(key_names)
    truth: dict[str, list[int]] = {}
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None or [h.strip() for h in header[:2]] != ["query", "key"]:
            raise VslamError(f"{path}: line 1: header must be 'query,key'")
        for line, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) < 2:
                raise VslamError(f"{path}: line {line}: expected 2 fields 'query,key', got {len(row)}")
            q, k = row[0].strip(), row[1].strip()
            if q not in q_index:
                raise VslamError(f"{path}: line {line}: field 'query': no query image named {q!r}")
            if k not in k_index:
                raise VslamError(f"{path}: line {line}: field 'key': no key image named {k!r}")
            truth.setdefault(query_names[q_index[q]], []).append(k_index[k])
    return truth


def _name_index(names: list[str]) -> dict[str, int]:
    index = {n: i for i, n in enumerate(names)}
    for i, n in enumerate(names):
        index.setdefault(Path(n).name, i)
    return index


def add_param_arguments(p: argparse.ArgumentParser, descriptor_default: str | None = "brief") -> None:
    g = p.add_argument_group("vocabulary parameters (defaults: the chosen preset)")
    g.add_argument("--descriptor", choices=DESCRIPTORS, default=descriptor_default, help="vocabulary kind")
    g.add_argument("--preset", default="default", help="parameter preset: default, paper (k=8, L=8), fast")
    g.add_argument("--k", type=int, help="branch factor of the vocabulary tree")
    g.add_argument("--depth", type=int, help="depth L of the vocabulary tree")
    g.add_argument("--distance", choices=DISTANCES, help="histogram comparison (default chi2)")
    g.add_argument("--min-shared", type=int, dest="min_shared_words", help="min words shared with a candidate key")
    g.add_argument("--theta", type=float, dest="rot_theta_deg", help="BRIEFROT rotation angle in degrees")
    g.add_argument("--n-features", type=int, dest="n_features", help="keypoints per image")
    g.add_argument("--patch", type=int, dest="brief_patch", help="BRIEF patch size in pixels")
    g.add_argument("--min-side", type=int, dest="min_image_side", help="upscale images with a shorter side below this")
    g.add_argument("--seed", type=int, help="vocabulary build seed")


def params_from_args(args: argparse.Namespace):
    from loops.vocab import preset

    fields = ("k", "depth", "distance", "min_shared_words", "rot_theta_deg", "n_features", "brief_patch",
              "min_image_side", "seed")
    overrides = {f: getattr(args, f) for f in fields if getattr(args, f, None) is not None}
    return preset(args.preset, descriptor=args.descriptor, **overrides)


# ---- the command -------------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION")
    sub.required = True
    b = sub.add_parser("build", help="build a visual memory file from key images")
    b.add_argument("memory_dir", help="image folder or sequence directory holding the key images")
    b.add_argument("--out", help="output file (default: ./<folder>.<descriptor>.vmem)")
    add_param_arguments(b)
    b.set_defaults(func=_run_build)

    q = sub.add_parser("query", help="rank the key images of a memory file for query images")
    q.add_argument("memory", help="a .vmem file written by `vslam localize build`")
    q.add_argument("images", nargs="+", help="query images (files or folders)")
    q.add_argument("--top", type=int, default=5, help="how many key images to print per query")
    q.add_argument("--csv", help="also write every ranking to this CSV (query,rank,key,score)")
    q.set_defaults(func=_run_query)

    e = sub.add_parser("eval", help="evaluate a descriptor on a memory + queries with ground truth (paper tables)")
    e.add_argument("memory_dir", help="key images: image folder or sequence directory")
    e.add_argument("queries_dir", help="query images: image folder or sequence directory")
    e.add_argument("--truth", required=True, help="CSV with header query,key (image names)")
    e.add_argument("--out", required=True, help="output folder: ranking.csv, per_query.csv, report.md, metrics.json")
    add_param_arguments(e, descriptor_default=None)
    e.set_defaults(func=_run_eval)


def run(args: argparse.Namespace) -> int:  # pragma: no cover - argparse dispatches to the action
    return args.func(args)


def _run_build(args: argparse.Namespace) -> int:
    import time

    from loops.vocab import VisualMemory

    params = params_from_args(args)
    items = list_images(args.memory_dir)
    t0 = time.perf_counter()
    memory = VisualMemory.build((read_image(p) for _, p in items), [n for n, _ in items], params)
    out = Path(args.out) if args.out else Path(f"{Path(args.memory_dir).resolve().name}.{params.descriptor.value}.vmem")
    memory.save(out)
    print(f"{memory.describe()}\nbuilt in {time.perf_counter() - t0:.1f} s -> {out} ({out.stat().st_size / 1e6:.2f} MB)")
    return 0


def _run_query(args: argparse.Namespace) -> int:
    import time

    from loops.vocab import NoFeaturesError, VisualMemory

    memory = VisualMemory.load(args.memory)
    items = []
    for spec in args.images:
        p = Path(spec)
        items += list_images(p) if p.is_dir() else [(p.name, p)]
    rows = []
    for name, path in items:
        image = read_image(path)
        t0 = time.perf_counter()
        try:
            ranking = memory.query(image, name=name)
        except NoFeaturesError as exc:
            print(f"{name}: {exc}")
            continue
        ms = (time.perf_counter() - t0) * 1e3
        best = ", ".join(f"{memory.key_names[k]} ({s:.3f})" for k, s in zip(ranking.keys[:args.top],
                                                                             ranking.scores[:args.top]))
        print(f"{name} [{ms:.1f} ms]: {best or 'no candidate key image'}")
        rows += [(name, i + 1, memory.key_names[k], float(s)) for i, (k, s) in enumerate(zip(ranking.keys, ranking.scores))]
    if args.csv:
        _write_csv(args.csv, ("query", "rank", "key", "score"), rows)
    return 0


def _write_csv(path, header, rows) -> None:
    from odometry.shared.atomic_io import atomic_write_text

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows([[f"{v:.6g}" if isinstance(v, float) else v for v in r] for r in rows])
    atomic_write_text(path, buf.getvalue())


def _run_eval(args: argparse.Namespace) -> int:
    if args.descriptor is None:
        raise VslamError("--descriptor is required for eval")
    from loops.vocab import VisualMemory, evaluate

    params = params_from_args(args)
    keys = list_images(args.memory_dir)
    queries = list_images(args.queries_dir)
    key_names, query_names = [n for n, _ in keys], [n for n, _ in queries]
    truth = read_truth(args.truth, query_names, key_names)
    if not truth:
        raise VslamError(f"{args.truth}: no ground-truth rows")
    memory = VisualMemory.build((read_image(p) for _, p in keys), key_names, params)
    ev = evaluate(memory, ((n, read_image(p), None) for n, p in queries), truth)
    write_report(Path(args.out), ev, memory, title=f"{Path(args.memory_dir).name} vs {Path(args.queries_dir).name}")
    print((Path(args.out) / "report.md").read_text())
    return 0


def write_report(out: Path, ev, memory, title: str) -> dict:
    """ranking.csv, per_query.csv, report.md, metrics.json and pr.png for one evaluation; returns the metrics."""
    from odometry.shared.atomic_io import atomic_write_text

    s = ev.summary()
    pr = ev.pr()
    params = memory.params
    _write_csv(out / "ranking.csv", ("query", "rank", "key", "score"), ev.ranking_rows(memory.key_names))
    _write_csv(out / "per_query.csv", ("query", "true_keys", "top1", "top1_score", "mu1", "mu2", "ms", "error"),
               [(r.name, ";".join(memory.key_names[k] for k in r.true_keys),
                 memory.key_names[int(r.ranking.keys[0])] if len(r.ranking) else "",
                 float(r.ranking.scores[0]) if len(r.ranking) else float("nan"), r.mu1, r.mu2, r.seconds * 1e3,
                 r.error) for r in ev.results])
    winners = ev.winner_counts(len(memory.angles)).tolist()
    metrics = {"title": title, "descriptor": params.descriptor.value, "params": params.to_dict(),
               "n_keys": len(memory), "n_tests": s.n_tests, "correct_mu1": s.correct_mu1,
               "effectiveness_mu1_pct": s.eff_mu1, "correct_mu2": s.correct_mu2, "effectiveness_mu2_pct": s.eff_mu2,
               "recall_at_1": s.recall1, "recall_at_5": s.recall5, "average_precision": s.average_precision,
               "median_ms_per_query": s.median_ms, "pattern_angles": list(memory.angles),
               "top1_vocabulary_counts": winners}
    atomic_write_text(out / "metrics.json", json.dumps(metrics, indent=2) + "\n")
    table = format_paper_table([(params.descriptor.label, s)])
    extra = ""
    if len(memory.angles) > 1:
        extra = "\nTop-1 vocabulary (pattern angle: count): " + ", ".join(
            f"{a:+g} deg: {c}" for a, c in zip(memory.angles, winners)) + "\n"
    atomic_write_text(out / "report.md", f"# {title}\n\n{memory.describe()}\n\n{table}\n{extra}")
    save_pr_plot(out / "pr.png", {params.descriptor.label: pr}, title)
    return metrics


PAPER_HEADERS = ("Descriptor", "Number of tests", "Correct tests mu1", "Effectiveness mu1 (%)", "Correct tests mu2",
                 "Effectiveness mu2 (%)", "Recall@1", "Recall@5", "AP", "Median time (ms)")


def format_paper_table(rows) -> str:
    """The paper's Tables 2-7 layout (+ Recall@1/5 and average precision); rows = [(label, Summary)]."""
    from vslam.bench._common import format_table

    return format_table(PAPER_HEADERS, [(label, s.n_tests, s.correct_mu1, round(s.eff_mu1, 2),
                                         "n/a" if s.correct_mu2 is None else s.correct_mu2,
                                         "n/a" if s.correct_mu2 is None else round(s.eff_mu2, 2),
                                         round(s.recall1, 3), round(s.recall5, 3),
                                         round(s.average_precision, 3), round(s.median_ms, 1)) for label, s in rows],
                        floatfmt=".4g")


def save_pr_plot(path: Path, curves: dict, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from odometry.shared.atomic_io import atomic_path

    fig, ax = plt.subplots(figsize=(5, 4), dpi=100)
    for label, pr in curves.items():
        ax.plot(pr.recall, pr.precision, label=f"{label} (AP {pr.average_precision:.2f})")
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
