"""A g2o pose graph through the robust optimiser: false loop closures are found and switched off.

    python examples/03_robust_pose_graph.py                # a small ring graph with some false loops added
    python examples/03_robust_pose_graph.py GRAPH.g2o      # any g2o / TORO file, e.g. one of the Vertigo sets

The same thing on the command line: `vslam graph optimize GRAPH.g2o --out OUT.g2o`.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from graph import PoseGraph, inject_false_loops, optimize, read_graph, write_graph
from odometry import between, compose


def ring_graph(path: Path, laps: int, per_lap: int, false_share: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Write a robot driving `laps` times around a 10 m circle to `path`; returns the true poses and which
    loops (in file order) are false."""
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi * laps, laps * per_lap, endpoint=False)
    truth = np.column_stack([5 * np.sin(a), 5 - 5 * np.cos(a), a])
    g, cov = PoseGraph(), np.diag([0.02, 0.02, 0.005]) ** 2
    guess = truth[0]
    g.add_node(0, guess)
    for i in range(1, len(truth)):             # odometry: the true motion plus noise; guesses chain it
        z = between(truth[i - 1], truth[i]) + rng.normal(0, [0.02, 0.02, 0.005])
        guess = compose(guess, z)
        g.add_node(i, guess)
        g.add_odometry(i - 1, i, z, cov)
    for i in range(per_lap, len(truth)):       # true loops: the same place one lap earlier
        g.add_loop(i, i - per_lap, between(truth[i], truth[i - per_lap]) + rng.normal(0, 0.01, 3), cov)
    data, injected = inject_false_loops(g.to_data(), false_share, seed)   # perceptual aliasing
    write_graph(path, data)
    return truth, injected[data.is_loop]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("graph", nargs="?", help="g2o or TORO file (default: generate a ring graph)")
    p.add_argument("--out", help="write the optimised graph here (g2o, or TORO for *.graph)")
    p.add_argument("--false-loops", type=float, default=0.2, help="false loops added, share of true (default 0.2)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        # 1. The input file: given, or a generated graph (3 laps of 40 nodes) with false loops appended.
        path, truth, false = Path(a.graph or Path(tmp) / "ring.g2o"), None, None
        if not a.graph:
            truth, false = ring_graph(path, laps=3, per_lap=40, false_share=a.false_loops, seed=0)
        data = read_graph(path)
    print(f"{path.name}: {data.num_nodes} nodes, {data.num_edges - data.num_loops} odometry edges, "
          f"{data.num_loops} loops")

    # 2. Plain least squares, plain graduated non-convexity on the loop factors, then the default robust mode
    #    (consensus: loops checked against short cycles of other loops, then GNC with odometry as known inliers).
    for robust in ("none", "gnc", "consensus"):
        res = optimize(data, robust=robust)
        line = (f"robust={robust:9s}: cost {res.initial_cost:.4g} -> {res.final_cost:.4g}, "
                f"loops kept {res.loops_kept}, rejected {res.loops_rejected}")
        if truth is not None and data.dim == 2:
            line += f", position RMSE vs truth {np.sqrt(np.mean(np.sum((res.poses[:, :2] - truth[:, :2]) ** 2, 1))):.3f} m"
        print(line)

    if false is not None:
        print(f"false loops: {int(false.sum())} added, {int((false & ~res.loop_inlier).sum())} rejected; true loops "
              f"kept {int((~false & res.loop_inlier).sum())} of {int((~false).sum())}")

    # 3. The robust result, written with the input's ids, edge order and information matrices.
    if a.out:
        write_graph(a.out, data, res.poses)
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
