"""Loops on slow revisits in the pipeline (issue 13): the README demo verified 165 candidates and accepted 1, and
`vslam run` reported recall 0.026 (1 of 38 positive queries) while `vslam eval` on the same run counted 2 positives.

Two causes, each tested here on the demo's own settings (our simulator, 10 m loop over carpet, seed 0):
- `vslam run` counted every keyframe that overlaps its predecessor as a positive query, ignoring the detector's
  exclusions (2 s and "the camera left the footprint"), which `vslam eval` applies from run.json;
- the closing keyframe before the last verifies its place with P(loop|score) 0.985, below the P = 1 threshold, and
  was refused although the motion gate confirms it.
"""
from __future__ import annotations

import pytest

from vslam.evaluation.run_eval import evaluate_result, evaluate_run
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.sim.simulate import SimConfig, simulate


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("demo")
    simulate(SimConfig(), root / "seq")
    seq = open_sequence(root / "seq")
    # keyframes 0.25 m apart: the keyframes this test was written on, whose closing one verifies below P = 1 (at
    # the default footprint spacing both closing keyframes of the demo verify at P = 1 and the gated path is idle)
    cfg = PipelineConfig().replace(recording={"enabled": False}, keyframes={"distance": 0.25})
    res = Pipeline(cfg).run(seq)
    return root, seq, res


def test_run_and_eval_count_the_same_positive_loop_queries(demo_run):
    root, seq, res = demo_run
    mine = evaluate_result(res, seq)["loops"]["accepted"]
    res.write(root / "out", evaluate=False, plots=False)
    theirs = evaluate_run(root / "out", make_plots=False)["loops"]["accepted"]
    assert mine["positive_queries"] == theirs["positive_queries"]
    assert mine["recall"] == theirs["recall"]
    assert mine["positive_queries"] < len(res.keyframes) // 4    # revisits only, not every neighbour


def test_the_demo_closes_its_loop_on_every_revisiting_keyframe(demo_run):
    _, seq, res = demo_run
    loops = evaluate_result(res, seq)["loops"]["accepted"]
    assert loops["precision"] == 1.0
    assert loops["positive_queries"] >= 2
    assert loops["recall"] == 1.0
    below = [l for l in res.accepted_loops if l.probability < 1.0]
    assert below and all(l.motion_consistent for l in below)
