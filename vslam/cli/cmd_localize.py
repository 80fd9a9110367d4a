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

from vslam.errors import VslamError

NAME = "localize"
HELP = "visual-memory localisation (vocabulary-tree bag of words): build, query, eval"
DESCRIPTORS = ("brief", "briefrot", "orb", "surf", "color-random", "color-whole", "color-half")
DISTANCES = ("chi2", "dot", "bhattacharyya", "l1", "l2")


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
    b.add_argument("--skip-bad-frames", action="store_true",
                   help="accept a frames.csv listing missing images (kept as keys that never match, with a warning)")
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
    e.add_argument("--skip-bad-frames", action="store_true",
                   help="accept frames.csv files listing missing images (a missing key never matches, a missing "
                        "query is a miss)")
    e.add_argument("--overwrite", action="store_true",
                   help="reuse a non-empty --out folder, removing the files eval writes (refused otherwise)")
    add_param_arguments(e, descriptor_default=None)
    e.set_defaults(func=_run_eval)


def run(args: argparse.Namespace) -> int:  # pragma: no cover - argparse dispatches to the action
    return args.func(args)


def _run_build(args: argparse.Namespace) -> int:
    from vslam.app.localize import build_memory  # on use: keeps `vslam --help` fast (see vslam.cli.main)

    print(build_memory(args.memory_dir, params_from_args(args), args.out,
                       skip_bad_frames=args.skip_bad_frames).summary())
    return 0


def _run_query(args: argparse.Namespace) -> int:
    from vslam.app.localize import query_memory

    query_memory(args.memory, args.images, top=args.top, csv=args.csv, echo=print)
    return 0


def _run_eval(args: argparse.Namespace) -> int:
    if args.descriptor is None:
        raise VslamError("--descriptor is required for eval")
    from vslam.app.localize import evaluate_memory

    print(evaluate_memory(args.memory_dir, args.queries_dir, args.truth, params_from_args(args), args.out,
                          skip_bad_frames=args.skip_bad_frames, overwrite=args.overwrite))
    return 0
