"""The SLAM pipeline end to end on a small simulated closed loop: outputs, recording, config, online use."""
import csv
import json
from dataclasses import replace

import numpy as np
import pytest

from odometry.shared.errors import ConfigError
from odometry.shared.tum import read_tum, tum_to_se2
from vslam.cli.main import main
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.sim import SimConfig, simulate

SIM = SimConfig(length=6.0, fps=15.0, speed=0.5, seed=4)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("pipeline")
    simulate(SIM, root / "seq")
    assert main(["run", str(root / "seq"), "--out", str(root / "out"), "--quiet"]) == 0
    return root


def test_outputs_exist_with_the_documented_columns(run_dir):
    out = run_dir / "out"
    for name in ("trajectory_vo.txt", "trajectory_slam.txt", "loops.csv", "graph.g2o", "metrics.json", "run.json",
                 "recording.rrd", "plots/trajectories.png", "plots/error_over_time.png"):
        assert (out / name).is_file(), name
    seq = open_sequence(run_dir / "seq")
    for name in ("trajectory_vo.txt", "trajectory_slam.txt"):
        t, p = read_tum(out / name)
        np.testing.assert_allclose(t, seq.timestamps, atol=1e-6)          # one pose per frame, same timestamps
        np.testing.assert_allclose(p[0], [0, 0, 0, 0, 0, 0, 1], atol=1e-9)  # the first pose at the origin
    with open(out / "loops.csv") as f:
        header = next(csv.reader(f))
    assert header == ["query_frame", "match_frame", "global_score", "local_score", "probability", "accepted", "inlier"]


def test_slam_is_accurate_and_closes_the_loop(run_dir):
    m = json.loads((run_dir / "out" / "metrics.json").read_text())
    ev = m["evaluation"]
    assert ev["slam"]["ape_rmse_percent_of_path"] < 1.0
    assert ev["slam"]["start_to_end"]["error_distance"] < 0.05
    s = m["summary"]
    assert s["frames"] == len(open_sequence(run_dir / "seq"))
    assert s["vo_status"]["ok"] >= s["frames"] - 2
    assert s["vo_frames_with_orb"] <= s["frames"] // 20                # 30 frames/s with wheel odometry: LK holds
    assert s["descriptor_bytes_max"] <= 4096                              # mode 4 budget
    assert s["loops_accepted"] >= 1 and ev["loops"]["accepted"]["precision"] == 1.0


def test_recording_contents(run_dir):
    from rerun.chunk import RrdReader

    seq_len = len(open_sequence(run_dir / "seq"))
    reader = RrdReader(str(run_dir / "out" / "recording.rrd"))
    paths = reader.store().schema().entity_paths()
    for p in ("/world/robot/camera/image", "/world/robot/camera/image/keypoints", "/world/robot/camera/image/matches",
              "/world/robot", "/world/floor", "/world/trajectory/gt", "/metrics/vo/inliers",
              "/metrics/timing/frame_ms", "/world/loops/kept", "/log"):
        assert p in paths, p
    # the defaults keep the file small: downscaled JPEG every 3rd frame (57 kB per frame before)
    assert (run_dir / "out" / "recording.rrd").stat().st_size / seq_len <= 10_000
    frames = []
    for ch in reader.stream().to_chunks():
        if ch.entity_path == "/metrics/vo/inliers" and not ch.is_static:
            frames += ch.to_record_batch().column("frame").to_pylist()
    assert sorted(frames) == list(range(seq_len))
    assert len(reader.blueprints()) == 1


def test_eval_command_reads_the_run(run_dir, capsys):
    assert main(["eval", str(run_dir / "out"), "--align", "se2"]) == 0
    rep = json.loads((run_dir / "out" / "eval.json").read_text())
    m = json.loads((run_dir / "out" / "metrics.json").read_text())
    # the run's own metrics (SE(2) alignment) and `vslam eval --align se2` agree
    assert rep["trajectories"]["SLAM"]["ape_m"]["rmse"] == pytest.approx(m["evaluation"]["slam"]["ape_m"]["rmse"],
                                                                          abs=1e-9)


def test_python_api_is_deterministic_and_online_step_matches_run(run_dir):
    seq = open_sequence(run_dir / "seq")
    cfg = replace(PipelineConfig(), recording=replace(PipelineConfig().recording, enabled=False))
    a = Pipeline(cfg).run(seq)
    b = Pipeline(cfg).run(seq)
    np.testing.assert_array_equal(a.poses_slam, b.poses_slam)
    t, p = read_tum(run_dir / "out" / "trajectory_slam.txt")
    np.testing.assert_allclose(a.poses_slam, tum_to_se2(p), atol=1e-6)
    # online: frame by frame, no wheel/gyro prior
    online = Pipeline(cfg, camera=seq.camera)
    for fr in seq.frames(gray=True):
        out = online.step(fr.image, fr.timestamp)
        assert out.index == fr.index and out.pose_vo.shape == (3,)
    res = online.finish()
    assert len(res.poses_slam) == len(seq) and len(res.keyframes) == len(a.keyframes)


def test_corrupt_frames_do_not_stop_the_run(tmp_path):
    from vslam.sim import Effects

    sim = replace(SIM, length=2.0, effects=replace(Effects.preset("none"), corrupt_frames=0.1), seed=7)
    res_sim = simulate(sim, tmp_path / "seq")
    assert res_sim.corrupt > 0
    cfg = replace(PipelineConfig(), recording=replace(PipelineConfig().recording, enabled=False))
    res = Pipeline(cfg).run(open_sequence(tmp_path / "seq"))
    bad = np.isin(res.vo_status, ["fallback", "lost"])
    assert bad.sum() >= res_sim.corrupt                        # each corrupt frame falls back (wheel/gyro)...
    assert np.all(np.isfinite(res.poses_slam))                 # ... and the run continues
    gt = open_sequence(tmp_path / "seq").groundtruth_planar()
    assert np.abs(res.poses_slam[:, :2] - gt[:, :2]).max() < 0.05


def test_config_files(tmp_path):
    y = tmp_path / "c.yaml"
    y.write_text("loops:\n  mode: 2\n  database: {confirmations: 2}\nvo: {max_features: 150}\nincremental: true\n")
    cfg = PipelineConfig.load(y)
    assert cfg.loops.mode == 2 and cfg.loops.database.confirmations == 2 and cfg.vo.max_features == 150
    assert cfg.incremental
    t = tmp_path / "c.toml"
    t.write_text("[loops]\nmode = 6\n[graph]\nrobust = \"huber\"\n")
    cfg = PipelineConfig.load(t)
    assert cfg.loops.mode == 6 and cfg.graph.robust.method.value == "huber"
    # round trip of the full default config
    d = tmp_path / "default.yaml"
    d.write_text(PipelineConfig().dumps())
    assert PipelineConfig.load(d) == PipelineConfig()


@pytest.mark.parametrize("text,match", [
    ("loops: {mdoe: 3}\n", r"c.yaml: loops.mdoe: unknown setting"),
    ("loops: {mode: 9}\n", r"c.yaml: loops: .*mode must be one of"),
    ("graph: {robust: maybe}\n", r"c.yaml: graph.robust.method: 'maybe' is not one of"),
    ("vo: {max_features: many}\n", r"c.yaml: vo.max_features: expected an integer"),
    ("loops: [1, 2\n", r"c.yaml: cannot parse"),
])
def test_bad_config_errors(tmp_path, text, match):
    y = tmp_path / "c.yaml"
    y.write_text(text)
    with pytest.raises(ConfigError, match=match):
        PipelineConfig.load(y)


def test_cli_errors(tmp_path, capsys, run_dir):
    y = tmp_path / "c.yaml"
    y.write_text("keyframes: {distnce: 1}\n")
    assert main(["run", str(run_dir / "seq"), "--out", str(tmp_path / "o"), "--config", str(y)]) == 2
    assert "keyframes.distnce: unknown setting" in capsys.readouterr().err
    cam_free = tmp_path / "imgs"
    cam_free.mkdir()
    import shutil

    for f in sorted((run_dir / "seq" / "images").iterdir())[:3]:
        shutil.copy(f, cam_free)
    assert main(["run", str(cam_free), "--out", str(tmp_path / "o2")]) == 2
    assert "no calibration" in capsys.readouterr().err
    assert main(["run", str(run_dir / "seq"), "--out", str(tmp_path / "o3"), "--print-config"]) == 0
    assert "loops:" in capsys.readouterr().out


def test_incremental_isam2_agrees_with_batch(run_dir):
    seq = open_sequence(run_dir / "seq")
    base = replace(PipelineConfig(), recording=replace(PipelineConfig().recording, enabled=False))
    batch = Pipeline(base).run(seq)
    inc = Pipeline(replace(base, incremental=True)).run(seq)
    assert inc.graph_result.solver == "isam2"
    assert np.abs(inc.poses_slam[:, :2] - batch.poses_slam[:, :2]).max() < 0.005
    assert [l.inlier for l in inc.loops if l.accepted] == [l.inlier for l in batch.loops if l.accepted]



def test_incremental_uses_verified_loops_online(tmp_path):
    """With --incremental, loops that fit the stated model enter the online estimate as they arrive, before the
    iSAM2 gate's empirical level has its 20 loops (two laps of a 4 m loop: the second lap closes loops mid-run)."""
    simulate(SimConfig(length=4.0, fps=15.0, speed=0.5, seed=4, laps=2), tmp_path / "seq")
    seq = open_sequence(tmp_path / "seq")
    cfg = replace(PipelineConfig(), incremental=True, recording=replace(PipelineConfig().recording, enabled=False))
    p = Pipeline(cfg, camera=seq.camera)
    at_arrival = []
    for frame in seq.frames(gray=True):
        out = p.step(frame.image, frame.timestamp)
        at_arrival += [rec.inlier for rec in out.loops if rec.loop_index is not None]
        if len(at_arrival) >= 20:
            break
    assert len(at_arrival) >= 5 and any(at_arrival[:5])
