"""`vslam run` / `vslam eval` on 1- and 2-frame sequences and on ground truth that does not move: every output is
written, the evaluation problem is a warning recorded in metrics.json / eval.json, exit 0."""
import json
import shutil

import numpy as np
import pytest

from vslam.cli.main import main

OUTPUTS = ("trajectory_vo.txt", "trajectory_slam.txt", "loops.csv", "graph.g2o", "run.json", "metrics.json",
           "plots/trajectories.png")


@pytest.fixture(scope="module")
def two_frames(tmp_path_factory):
    seq = tmp_path_factory.mktemp("short") / "s2"
    assert main(["simulate", str(seq), "--frames", "2", "--quiet"]) == 0
    return seq


def one_frame(two_frames, tmp_path):
    seq = tmp_path / "s1"
    shutil.copytree(two_frames, seq)
    lines = (seq / "frames.csv").read_text().splitlines()
    (seq / "frames.csv").write_text("\n".join(lines[:2]) + "\n")
    return seq


def still_groundtruth(two_frames, tmp_path):
    seq = tmp_path / "still"
    shutil.copytree(two_frames, seq)
    t = [float(line.split()[0]) for line in (seq / "groundtruth.txt").read_text().splitlines()
         if line.strip() and not line.startswith("#")]
    (seq / "groundtruth.txt").write_text("".join(f"{x!r} 1 2 0 0 0 0 1\n" for x in t))
    return seq


@pytest.mark.parametrize("make", ["two", "one", "still"])
def test_run_and_eval_write_everything_and_record_the_problem(two_frames, tmp_path, capsys, make):
    seq = {"two": lambda: two_frames, "one": lambda: one_frame(two_frames, tmp_path),
           "still": lambda: still_groundtruth(two_frames, tmp_path)}[make]()
    out = tmp_path / "out"
    assert main(["run", str(seq), "--out", str(out), "--no-recording", "--quiet"]) == 0
    for name in OUTPUTS:
        assert (out / name).is_file(), name
    ev = json.loads((out / "metrics.json").read_text())["evaluation"]
    assert ev["problems"] and all(("vo" in p or "slam" in p) for p in ev["problems"])
    assert "warning: evaluation skipped" in capsys.readouterr().err
    assert np.loadtxt(out / "trajectory_slam.txt", ndmin=2).shape[0] == (1 if make == "one" else 2)

    assert main(["eval", str(out)]) == 0
    rep = json.loads((out / "eval.json").read_text())
    assert rep["problems"] and "not evaluated" in capsys.readouterr().out
