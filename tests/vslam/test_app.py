"""The library functions behind the commands, called directly (the CLI tests run them through `vslam ...`)."""
from __future__ import annotations

import numpy as np
import pytest

from loops.errors import LoopsError
from loops.horizon import HorizonLine, HorizonParams
from loops.horizon.pairs_file import parse_horizon, read_scored_pairs
from vslam.app.graph import graph_file_info, optimize_graph_file
from vslam.app.horizon import apply_overrides, evaluate_scores
from vslam.app.odometry import parse_overrides
from vslam.errors import VslamError
from vslam.evaluation.tables import format_table
from vslam.io.truth_csv import read_truth, write_truth

from .test_cli_graph import GRAPH


def test_horizon_rows_and_overrides():
    assert parse_horizon(" 183 ", "x") == 183.0
    assert parse_horizon("180:186", "x") == HorizonLine(180.0, 186.0)
    with pytest.raises(LoopsError, match=r"^f line 2, field row_a: 'a:b:c' is not a horizon row"):
        parse_horizon("a:b:c", "f line 2, field row_a")
    params = apply_overrides(HorizonParams.preset("paper"), ["threshold=20", "ratio=0.7"])
    assert params.threshold == 20 and params.ratio == 0.7
    with pytest.raises(VslamError, match="unknown HorizonParams field"):
        apply_overrides(HorizonParams(), ["nonsense=1"])
    assert parse_overrides(["max_features=300", "refine_tilt=false"]) == {"max_features": 300, "refine_tilt": False}
    with pytest.raises(VslamError, match="expected KEY=VALUE"):
        parse_overrides(["max_features"])


def test_evaluate_scores_reports_through_echo(tmp_path):
    scores = tmp_path / "scores.csv"
    rows = ["label,score,score_ransac"] + [f"1,{10 + i},{20 + i}" for i in range(5)] + [f"0,{i},{i}" for i in range(5)]
    scores.write_text("\n".join(rows) + "\n")
    lines: list[str] = []
    aucs = evaluate_scores(scores, plot=tmp_path / "roc.png", echo=lines.append)
    assert aucs == {"NN": 1.0, "NN+RANSAC": 1.0}
    assert lines[0] == "10 pairs: 5 matched, 5 unmatched" and lines[-1] == f"wrote {tmp_path / 'roc.png'}"
    assert (tmp_path / "roc.png").stat().st_size > 0
    scores.write_text("label,score,score_ransac\n1,2,3\n2,1,1\n")
    with pytest.raises(LoopsError, match=r"line 3, field label: 2 is not 0 or 1"):
        read_scored_pairs(scores)
    scores.write_text("label,score,score_ransac\n1,2,3\n1,1,1\n")
    with pytest.raises(VslamError, match="need both label 1 and label 0"):
        evaluate_scores(scores)


def test_truth_csv_round_trip(tmp_path):
    keys = ["k/a.png", "k/b.png", "c.png"]
    truth = {"q1.png": [0, 2], "q2.png": [1]}
    write_truth(tmp_path / "truth.csv", truth, keys)
    assert (tmp_path / "truth.csv").read_text() == "query,key\nq1.png,k/a.png\nq1.png,c.png\nq2.png,k/b.png\n"
    assert read_truth(tmp_path / "truth.csv", ["q1.png", "q2.png"], keys) == truth
    (tmp_path / "bad.csv").write_text("query,key\nq1.png,nope.png\n")
    with pytest.raises(VslamError, match=r"bad.csv: line 2: field 'key': no key image named 'nope.png'"):
        read_truth(tmp_path / "bad.csv", ["q1.png"], keys)


def test_graph_files(tmp_path):
    src = tmp_path / "in.g2o"
    src.write_text(GRAPH)
    assert graph_file_info(src) == f"{src}: 4 vertices (SE(2)), 4 edges: 3 odometry, 1 loops"
    run = optimize_graph_file(src, tmp_path / "out.g2o", robust="gnc", solver="lm")
    assert run.finite and run.lines[0] == graph_file_info(src) and run.lines[-1] == f"wrote {tmp_path / 'out.g2o'}"


def test_format_table():
    assert format_table(["a", "b"], [[1, 0.123456], ["x", np.float64(2.0)]]) == (
        "| a | b |\n|---|---|\n| 1 | 0.123 |\n| x | 2 |")
