"""`vslam train-loops SEQ... --out loops-model.json`: learn P(loop | local score) and the per-mode thresholds
(see `vslam.app.train_loops`)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vslam.errors import VslamError

NAME = "train-loops"
HELP = "learn the loop model P(loop|score) and per-mode thresholds from odometry-labelled sequences"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequences", nargs="+", help="training sequence directories (with odometry.csv)")
    p.add_argument("--out", required=True, help="model JSON to write (a PNG of the curves is written beside it)")
    p.add_argument("--modes", default="1,2,3,4,5,6", help="comma-separated modes (default all)")
    p.add_argument("--overlap", type=float, default=0.33, help="loop when the footprint overlap J >= this (r)")
    p.add_argument("--every", type=int, default=1, help="use every N-th frame as a keyframe (default 1)")
    p.add_argument("--exclude-recent", type=int, default=5,
                   help="do not pair keyframes closer than this many keyframes (default 5)")
    p.add_argument("--shortlist", type=int, default=5, help="global candidates per query, as at run time")
    p.add_argument("--random", type=int, default=5, help="random earlier keyframes per query (negatives)")
    p.add_argument("--max-sigma", type=float, default=0.02,
                   help="use a pair's label only if the fused relative position is known to this many metres "
                        "(or the images are certainly apart); default 0.02")
    p.add_argument("--min-overlap", type=float, default=None,
                   help="a loop also needs the overlap implied by the verified transform >= this (default: the "
                        "overlap threshold + 0.05; a negative value turns the check off)")
    p.add_argument("--cache", help="directory to keep per-sequence pair scores (re-fits skip the matching)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-plot", action="store_true")
    p.add_argument("--quiet", action="store_true")


def _parse_modes(text: str) -> tuple[int, ...]:
    try:
        modes = tuple(sorted({int(m) for m in text.split(",") if m.strip()}))
    except ValueError:
        raise VslamError(f"--modes: expected comma-separated integers 1-6, got {text!r}") from None
    if not modes or any(m < 1 or m > 6 for m in modes):
        raise VslamError(f"--modes: modes must be in 1..6, got {text!r}")
    return modes


def run(a: argparse.Namespace) -> int:
    from vslam.app.train_loops import PairSampling, train_loop_model  # on use: keeps `vslam --help` fast

    modes = _parse_modes(a.modes)
    command = ("vslam train-loops " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["train-loops"]
               else "vslam train-loops")
    sampling = PairSampling(every=a.every, exclude_recent=a.exclude_recent, shortlist=a.shortlist, random=a.random,
                            seed=a.seed, max_sigma=a.max_sigma)
    model = train_loop_model(a.sequences, a.out, modes, a.overlap, sampling, min_overlap=a.min_overlap,
                             cache=a.cache, plot=not a.no_plot, command=command,
                             log=None if a.quiet else (lambda line: print(line, file=sys.stderr)))
    if not a.quiet:
        for m in modes:
            print(f"mode {m}: threshold {model.threshold(m):.3g}")
        out = Path(a.out)
        print(f"wrote {out}" + ("" if a.no_plot else f" and {out.with_suffix('.png')}"))
    return 0
