"""Visual-memory localisation: a vocabulary tree over key images, queried with images taken later.

    python examples/04_visual_memory_localisation.py       # keys from lap 1 of a simulated loop, queries from lap 2
    python examples/04_visual_memory_localisation.py SEQ   # keys from the first half of SEQ, queries from the second

"Where am I?" with no pose prior (the kidnapped robot): rank every key image by bag-of-words similarity. With
ground truth, the rank of the nearest key image says how well that worked (1 = found first).
The same thing on the command line: `vslam localize build|query|eval`.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import vslam
from loops.vocab import PRESETS, VisualMemory, full_ranks, preset
from vslam.sim import SimConfig, simulate


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sequence", nargs="?", help="sequence driving the same places twice (default: simulate one)")
    p.add_argument("--step", type=int, default=3, help="every STEP-th frame is a key or a query (default 3)")
    p.add_argument("--preset", default="fast", choices=sorted(PRESETS), help="vocabulary preset (default fast)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        # 1. The input: a 4 m loop driven twice, or a given sequence; split into a mapping and a query half.
        path = Path(a.sequence) if a.sequence else Path(tmp) / "seq"
        if not a.sequence:
            simulate(SimConfig(width=320, height=240, focal=250.0, length=4.0, laps=2, turn_radius=0.6, fps=5.0,
                               seed=3), path)
        seq = vslam.open_sequence(path)
        half = len(seq) // 2
        keys = list(range(0, half, a.step))
        queries = list(range(half, len(seq), a.step))

        # 2. Build the memory: features of every key image, a k-means vocabulary tree, an inverted index.
        memory = VisualMemory.build((seq.image(i, gray=True) for i in keys), [f"frame {i}" for i in keys],
                                    preset(a.preset))
        print(memory.describe())

        # 3. Query: each later image gets a ranking of the key images, best first.
        rankings = [memory.query(seq.image(q, gray=True)) for q in queries]
        gt = seq.groundtruth_planar()

    # 4. With ground truth: the rank of the key image nearest to where each query was taken.
    if gt is None:
        for q, r in zip(queries, rankings):
            print(f"frame {q}: best keys {[memory.key_names[k] for k in r.keys[:3]]}")
        return 0
    ranks = []
    for q, r in zip(queries, rankings):
        nearest = int(np.argmin(np.hypot(*(gt[keys, :2] - gt[q, :2]).T)))
        ranks.append(full_ranks(r.keys, len(keys))[nearest])
    ranks = np.asarray(ranks)
    print("rank of the nearest key image per query:", " ".join(f"{x:.0f}" for x in ranks))
    print(f"{len(queries)} queries against {len(keys)} keys: found first {np.mean(ranks == 1) * 100:.0f} %, "
          f"in the top 3 {np.mean(ranks <= 3) * 100:.0f} %, mean rank {ranks.mean():.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
