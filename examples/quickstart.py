"""vslam quick start: simulate -> train the loop model -> run SLAM -> evaluate -> open in Rerun.

    python examples/quickstart.py [WORKDIR]          # default WORKDIR: ./quickstart

Every step is also a command (shown in the comments), so this script doubles as a recipe for the shell.
It takes a few minutes on a laptop.
"""
from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

from vslam.cli.main import main as vslam_cli
from vslam.evaluation.run_eval import evaluate_run, format_report
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.recording import RunRecorder
from vslam.sim import SimConfig, simulate

work = Path(sys.argv[1] if len(sys.argv) > 1 else "quickstart")
work.mkdir(parents=True, exist_ok=True)

# 1. Training sequences: natural carpet and the printed-wood worst case, with revisits (lawnmower).
#    vslam simulate WORK/train-carpet --floor carpet --trajectory lawnmower --length 20 --seed 1
train = []
for floor, seed in (("carpet", 1), ("printed-wood", 2)):
    path = work / f"train-{floor}"
    if not (path / "frames.csv").exists():
        simulate(SimConfig(floor=floor, trajectory="lawnmower", length=20.0, seed=seed), path)
    train.append(str(path))

# 2. Learn P(loop | score) and the mode threshold from them; relative motion comes from wheel odometry + gyro.
#    vslam train-loops WORK/train-carpet WORK/train-printed-wood --modes 4 --out WORK/loop-model.json
model = work / "loop-model.json"
if not model.exists():
    vslam_cli(["train-loops", *train, "--modes", "4", "--out", str(model)])

# 3. A test sequence: a 20 m closed loop over concrete, run through SLAM with the trained model.
#    vslam simulate WORK/test --floor concrete --length 20 --seed 3
#    vslam run WORK/test --out WORK/run --mode 4 --loop-model WORK/loop-model.json
test = work / "test"
if not (test / "frames.csv").exists():
    simulate(SimConfig(floor="concrete", length=20.0, seed=3), test)
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
