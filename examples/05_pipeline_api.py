"""The whole SLAM pipeline through the Python API: open a sequence, run it, write the outputs, read the ATE.

    python examples/05_pipeline_api.py --out run           # renders a short closed loop driven twice first
    python examples/05_pipeline_api.py SEQ --out run       # any sequence with a downward camera.yaml

The same thing on the command line: `vslam run SEQ --out run` (which also writes a Rerun recording).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import vslam
from vslam.sim import SimConfig, simulate


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sequence", nargs="?", help="sequence with a downward camera (default: simulate one)")
    p.add_argument("--out", default="pipeline_run", help="output folder (default ./pipeline_run)")
    a = p.parse_args(argv)
    # 1. The input: a given sequence, or a 4 m loop driven twice at 10 frames/s rendered into OUT/sequence
    #    (kept, so that `vslam eval OUT` finds it later). Frames are read lazily.
    path = Path(a.sequence) if a.sequence else Path(a.out) / "sequence"
    if not a.sequence:
        simulate(SimConfig(width=320, height=240, focal=250.0, length=4.0, laps=2, turn_radius=0.6, fps=10.0,
                           seed=4), path, overwrite=True)
    seq = vslam.open_sequence(path)

    # 2. Run: visual odometry (fused with wheels and gyro when the sequence has them), loop detection with
    #    compact descriptors, and the robust pose graph. PipelineConfig() holds the defaults of `vslam run`.
    result = vslam.Pipeline(vslam.PipelineConfig()).run(seq)
    s = result.summary()
    print(f"{s['frames']} frames, {s['keyframes']} keyframes; {s['loops_accepted']} loops accepted, "
          f"{s['loops_kept']} kept by the pose graph")

    # 3. Write trajectories (TUM), loops.csv, graph.g2o, metrics.json and plots; with the sequence given,
    #    metrics.json also holds the evaluation against its ground truth.
    out = result.write(a.out, sequence=seq)
    print(f"wrote {out}: {', '.join(sorted(f.name for f in out.iterdir()))}")

    # 4. The absolute trajectory error (SE(2)-aligned RMSE, evo's convention) of odometry alone and of SLAM.
    metrics = json.loads((out / "metrics.json").read_text())
    if "evaluation" not in metrics:
        print("the sequence has no ground truth: no ATE")
        return 0
    for name in ("vo", "slam"):
        e = metrics["evaluation"][name]
        print(f"ATE {name:4s}: {e['ape_m']['rmse'] * 100:.2f} cm RMSE over {e['path_length_m']:.2f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
