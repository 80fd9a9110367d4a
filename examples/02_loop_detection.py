"""Loop detection only: compact (CDVS-style) descriptors of each frame, queried against the earlier ones.

    python examples/02_loop_detection.py                   # renders a short closed loop driven twice
    python examples/02_loop_detection.py SEQ --step 4      # any sequence (every 4th frame is a keyframe)

No odometry or calibration is needed to detect loops; ground truth, when the sequence has it, only tells which
detections are real revisits. The same thing on the command line: `vslam loops SEQ --mode 4 --out DIR`.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

import vslam
from loops.cdvs import LoopDatabase, LoopModel, decode, encode
from vslam.sim import SimConfig, simulate


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("sequence", nargs="?", help="any sequence (default: simulate a 4 m loop driven twice)")
    p.add_argument("--mode", type=int, default=4, help="descriptor mode 1..6: at most 512 B ... 16 kB (default 4)")
    p.add_argument("--step", type=int, default=1, help="use every STEP-th frame as a keyframe (default 1)")
    p.add_argument("--show", type=int, default=10, help="loops to list (default 10)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        # 1. The input: two laps of a small closed loop at 5 frames/s, so the second lap revisits the first.
        path = Path(a.sequence) if a.sequence else Path(tmp) / "seq"
        if not a.sequence:
            simulate(SimConfig(width=320, height=240, focal=250.0, length=4.0, laps=2, turn_radius=0.6, fps=5.0,
                               seed=2), path)
        seq = vslam.open_sequence(path)

        # 2. The database holds one descriptor per keyframe; the shipped model turns a score into P(loop).
        db = LoopDatabase(a.mode, model=LoopModel.default())
        loops, sizes = [], []
        for frame in seq.frames(gray=True, step=a.step):
            data = encode(frame.image, a.mode)       # the bytes a robot would store or send
            d = decode(data)
            sizes.append(len(data))
            # 3. Query before adding: candidates come only from earlier keyframes (the most recent are skipped).
            #    They come best first; keep the best accepted one per keyframe.
            accepted = [c for c in db.query(d, frame.index) if c.accepted]
            loops += [(frame.index, accepted[0])] if accepted else []
            db.add(frame.index, d)
        gt = seq.groundtruth_planar()

    # 4. Report; with ground truth, a detection is a real revisit when the two frames were taken close together.
    print(f"{len(db)} keyframes, descriptors {np.mean(sizes):.0f} B on average; {len(loops)} of them close a loop")
    true = 0
    for k, (q, c) in enumerate(loops):
        dist = float(np.hypot(*(gt[q, :2] - gt[c.frame_id, :2]))) if gt is not None else float("nan")
        true += bool(dist < 0.3)
        if k < a.show:
            print(f"  frame {q:4d} -> {c.frame_id:4d}  local score {c.local_score:6.1f}  P(loop) {c.probability:.2f}"
                  f"  {dist:.2f} m apart")
    if gt is not None:
        print(f"{true} of {len(loops)} detections are within 0.3 m of each other in the ground truth")
    return 0


if __name__ == "__main__":
    sys.exit(main())
