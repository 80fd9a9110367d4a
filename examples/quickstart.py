"""vslam quick start: simulate -> train the loop model -> run SLAM -> evaluate -> open in Rerun.

    python examples/quickstart.py [WORKDIR]                    # default WORKDIR: ./quickstart; a few minutes
    python examples/quickstart.py WORKDIR --length 4 --turn-radius 0.3 --size 320x240 --fps 4   # small

Every step is also a command (shown in the comments), so this script doubles as a recipe for the shell.
Steps whose output already exists in WORKDIR are skipped.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

from vslam.evaluation.run_eval import evaluate_run, format_report
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.recording import RunRecorder
from vslam.sim import SimConfig, simulate


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("workdir", nargs="?", default="quickstart", help="where everything is written (default ./quickstart)")
    p.add_argument("--length", type=float, default=20.0, help="metres per simulated sequence (default 20)")
    p.add_argument("--size", default="640x480", help="image size WxH (default 640x480)")
    p.add_argument("--fps", type=float, default=20.0, help="camera frame rate (default 20)")
    p.add_argument("--turn-radius", type=float, default=1.0, help="metres (default 1; smaller for short --length)")
    a = p.parse_args(argv)
    work = Path(a.workdir)
    work.mkdir(parents=True, exist_ok=True)
    w, h = (int(v) for v in a.size.split("x"))
    sim = SimConfig(length=a.length, width=w, height=h, focal=500.0 * w / 640, fps=a.fps,
                    turn_radius=a.turn_radius)

    # 1. Training sequences: natural carpet and the printed-wood worst case, with revisits (lawnmower).
    #    vslam simulate WORK/train-carpet --floor carpet --trajectory lawnmower --length 20 --seed 1
    train = []
    for floor, seed in (("carpet", 1), ("printed-wood", 2)):
        path = work / f"train-{floor}"
        if not (path / "frames.csv").exists():
            simulate(replace(sim, floor=floor, trajectory="lawnmower", seed=seed), path, overwrite=True)
        train.append(str(path))

    # 2. Learn P(loop | score) and the mode threshold from them; relative motion comes from wheel odometry + gyro.
    #    vslam train-loops WORK/train-carpet WORK/train-printed-wood --modes 4 --out WORK/loop-model.json
    model = work / "loop-model.json"
    if not model.exists():
        cmd = [sys.executable, "-m", "vslam", "train-loops", *train, "--modes", "4", "--out", str(model), "--quiet"]
        sys.stdout.flush()
        if subprocess.run(cmd).returncode != 0:
            print("vslam train-loops failed", file=sys.stderr)
            return 1

    # 3. A test sequence: a closed loop over concrete, run through SLAM with the trained model.
    #    vslam simulate WORK/test --floor concrete --length 20 --seed 3
    #    vslam run WORK/test --out WORK/run --mode 4 --loop-model WORK/loop-model.json
    test = work / "test"
    if not (test / "frames.csv").exists():
        simulate(replace(sim, floor="concrete", seed=3), test, overwrite=True)
    seq = open_sequence(test)
    config = PipelineConfig()
    config = replace(config, loops=replace(config.loops, mode=4, model=str(model)))
    out = work / "run"
    out.mkdir(exist_ok=True)
    recorder = RunRecorder(out / "recording.rrd", seq.camera)
    result = Pipeline(config, recorder=recorder).run(seq)
    recorder.close()
    result.write(out, sequence=seq)
    s = result.summary()
    print(f"{s['frames']} frames at {s['frames_per_second']:.0f} frames/s; {s['loops_accepted']} loops accepted, "
          f"{s['loops_kept']} kept by the back end")

    # 4. Evaluate against ground truth (ATE/RPE as evo computes them, start-to-end error, loop precision/recall).
    #    vslam eval WORK/run --align se2
    print(format_report(evaluate_run(out, alignment="se2")))

    # 5. Look at it: the plots in WORK/run/plots/, and the recording in the Rerun viewer.
    print(f"\nopen the recording with:  rerun {out / 'recording.rrd'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
