"""`vslam odometry` on a small simulated sequence with corrupt and dropped frames."""
from __future__ import annotations

import numpy as np
import pytest

from odometry.shared.poses import between
from odometry.shared.tum import read_tum, tum_to_se2
from vslam.cli.main import main


@pytest.fixture(scope="module")
def faulty_sequence(tmp_path_factory):
    from dataclasses import replace

    from vslam.sim import Effects, SimConfig, simulate

    out = tmp_path_factory.mktemp("seq") / "faulty"
    cfg = SimConfig(length=1.2, max_frames=40, seed=3,
                    effects=replace(Effects(), dropped_frames=0.1, corrupt_frames=0.1))
    res = simulate(cfg, out)
    assert res.corrupt > 0 and res.dropped > 0  # the seed gives both kinds of faults
    return out


def test_cli_writes_a_tum_trajectory_and_per_frame_statistics(faulty_sequence, tmp_path, capsys):
    from vslam.io import open_sequence

    out = tmp_path / "vo"
    assert main(["odometry", str(faulty_sequence), "--out", str(out), "--quiet"]) == 0
    seq = open_sequence(faulty_sequence)
    t, tum = read_tum(out / "trajectory_vo.txt")
    assert np.array_equal(np.round(t, 6), np.round(seq.timestamps, 6))  # one pose per input frame, same times
    poses = tum_to_se2(tum)
    assert np.allclose(poses[0], 0.0)
    rows = (out / "odometry.csv").read_text().splitlines()
    assert rows[0].split(",")[:4] == ["index", "timestamp", "status", "reference"] and len(rows) == len(seq) + 1
    status = [r.split(",")[2] for r in rows[1:]]
    assert "fallback" in status                            # the corrupt frames
    assert status.count("ok") >= len(seq) - 8
    gt = seq.groundtruth_planar()
    err = np.hypot(*(poses[-1, :2] - between(gt[0], gt)[-1, :2]))
    assert err < 0.01                                      # 1 cm over ~1 m, despite the faults
    assert (out / "trajectory_fused.txt").is_file()
    assert "by vision" in capsys.readouterr().out


def test_cli_bad_input_exits_2(tmp_path, capsys):
    assert main(["odometry", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "missing" in capsys.readouterr().err


def test_cli_rejects_unknown_config_override(faulty_sequence, tmp_path, capsys):
    assert main(["odometry", str(faulty_sequence), "--out", str(tmp_path / "o"), "--set", "bogus=1"]) == 2
    assert "bogus" in capsys.readouterr().err
