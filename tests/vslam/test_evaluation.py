"""Evaluation metrics agree with evo on the same inputs (to 1e-6), plus loop metrics and the eval command."""
import json
import math

import numpy as np
import pytest

evo = pytest.importorskip("evo", reason="evo is a test dependency (pip install -e .[test])")
from evo.core import metrics as em
from evo.core import sync
from evo.core.trajectory import PoseTrajectory3D

from odometry.shared.camera import CameraModel
from odometry.shared.poses import integrate
from odometry.shared.tum import se2_to_tum, tum_to_se3_matrices, write_tum
from vslam.cli.main import main
from vslam.evaluation import Alignment, evaluate, start_to_end_error
from vslam.evaluation.loops import LoopTable, loop_precision_recall


def _trajectories(seed=0, n=240):
    rng = np.random.default_rng(seed)
    p = integrate(np.column_stack([rng.normal(0.05, 0.01, n - 1), rng.normal(0, 0.005, n - 1),
                                   rng.normal(0, 0.03, n - 1)]))
    ref = tum_to_se3_matrices(se2_to_tum(p))
    ref[:, 2, 3] = rng.normal(0, 0.01, n)                  # not exactly planar
    est = ref.copy()
    est[:, :3, 3] = est[:, :3, 3] * 0.93 + rng.normal(0, 0.02, (n, 3))
    th = 0.4
    rz = np.array([[math.cos(th), -math.sin(th), 0], [math.sin(th), math.cos(th), 0], [0, 0, 1]])
    est[:, :3, :3] = rz @ est[:, :3, :3]
    est[:, :3, 3] = est[:, :3, 3] @ rz.T + [1.0, -2.0, 0.3]
    t = np.arange(n) * 0.1
    return t, ref, t[::2] + 0.004, est[::2]                # half rate, small time offset: association matters


def _evo(t, m):
    return PoseTrajectory3D(poses_se3=list(m), timestamps=t)


@pytest.mark.parametrize("mode", ["none", "se3", "sim3"])
@pytest.mark.parametrize("delta,unit", [(1, "f"), (4, "f"), (1.5, "m")])
def test_matches_evo(mode, delta, unit):
    t, ref, te, est = _trajectories()
    r, e = sync.associate_trajectories(_evo(t, ref), _evo(te, est), max_diff=0.01)
    if mode != "none":
        e.align(r, correct_scale=mode == "sim3")
    ours = evaluate(t, ref, te, est, mode, max_diff=0.01, delta=delta, delta_unit=unit)
    evo_unit = em.Unit.frames if unit == "f" else em.Unit.meters
    checks = [(em.APE(em.PoseRelation.translation_part), ours.ape),
              (em.APE(em.PoseRelation.rotation_angle_deg), ours.ape_rot_deg),
              (em.RPE(em.PoseRelation.translation_part, delta=delta, delta_unit=evo_unit), ours.rpe),
              (em.RPE(em.PoseRelation.rotation_angle_deg, delta=delta, delta_unit=evo_unit), ours.rpe_rot_deg)]
    for metric, stats in checks:
        metric.process_data((r, e))
        for name in ("rmse", "mean", "median", "max", "min"):
            assert stats[name] == pytest.approx(metric.get_statistic(em.StatisticsType(name)), abs=1e-6), name
    assert ours.matched == r.num_poses


def test_se2_alignment_equals_evo_se3_on_planar_data():
    t, ref, te, est = _trajectories(1)
    ref[:, 2, 3] = 0.0
    est[:, 2, 3] = 0.0
    r, e = sync.associate_trajectories(_evo(t, ref), _evo(te, est), max_diff=0.01)
    e.align(r)
    a = em.APE(em.PoseRelation.translation_part)
    a.process_data((r, e))
    assert evaluate(t, ref, te, est, Alignment.SE2).ape["rmse"] == pytest.approx(
        a.get_statistic(em.StatisticsType.rmse), abs=1e-6)


def test_se2_alignment_ignores_height():
    t, ref, te, est = _trajectories(2)
    est[:, 2, 3] += 5.0                                     # a height offset SE(2) cannot and should not fix
    assert evaluate(t, ref, te, est, "se2").ape["rmse"] > 4.9
    assert evaluate(t, ref, te, est, "se3").ape["rmse"] < 1.0


def test_start_to_end_error_hand_case():
    est = np.array([[0, 0, 0], [5, 0, 1.0], [0.03, -0.04, 0.01]])
    gt = np.array([[0, 0, 0], [5, 0, 1.0], [0.0, 0.0, 0.0]])
    r = start_to_end_error(est, gt)
    assert r["distance"] == pytest.approx(0.05) and r["error_distance"] == pytest.approx(0.05)
    assert r["true_distance"] == 0.0 and r["error_dtheta"] == pytest.approx(0.01)


def test_loop_precision_recall_toy():
    cam = CameraModel(640, 480, 500.0, 500.0, 319.5, 239.5, camera_height=0.5)
    # frames 0..9 along x every 0.5 m, then frame 10 back at frame 2's place, frame 11 at frame 6's place
    gt = np.array([[0.5 * i, 0, 0] for i in range(10)] + [[1.0, 0.02, 0.0], [3.0, 0, 0.0]])
    loops = LoopTable(query=np.array([10, 11, 11]), match=np.array([2, 6, 1]), global_score=np.ones(3),
                      local_score=np.ones(3), probability=np.ones(3), accepted=np.array([True, True, False]),
                      inlier=None)
    pr = loop_precision_recall(cam, gt, loops, queried=np.arange(12), min_separation=3)
    assert pr["true_positives"] == 2 and pr["false_positives"] == 0 and pr["precision"] == 1.0
    assert pr["positive_queries"] == 2 and pr["recall"] == 1.0
    wrong = LoopTable(query=np.array([10]), match=np.array([7]), global_score=np.ones(1), local_score=np.ones(1),
                      probability=np.ones(1), accepted=np.array([True]), inlier=None)
    pr = loop_precision_recall(cam, gt, wrong, queried=np.arange(12), min_separation=3)
    assert pr["precision"] == 0.0 and pr["recall"] == 0.0


def test_eval_command(tmp_path, capsys):
    t, ref, _, _ = _trajectories(3)
    gt = tmp_path / "gt.txt"
    tum = np.column_stack([ref[:, :3, 3], np.zeros((len(ref), 3)), np.ones(len(ref))])
    write_tum(gt, t, tum)
    run = tmp_path / "run"
    run.mkdir()
    noisy = tum.copy()
    noisy[:, :2] += np.random.default_rng(0).normal(0, 0.01, (len(tum), 2))
    write_tum(run / "trajectory_slam.txt", t, noisy)
    assert main(["eval", str(run), "--gt", str(gt), "--align", "se2"]) == 0
    rep = json.loads((run / "eval.json").read_text())
    assert 0.005 < rep["trajectories"]["SLAM"]["ape_m"]["rmse"] < 0.02
    assert (run / "plots" / "trajectories.png").is_file() and (run / "plots" / "error_over_time.png").is_file()
    assert "SLAM" in capsys.readouterr().out
    assert main(["eval", str(tmp_path / "missing"), "--gt", str(gt)]) == 2
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["eval", str(empty), "--gt", str(gt)]) == 2
    assert "no trajectory" in capsys.readouterr().err


def test_loop_recall_counts_only_revisits_the_detector_could_report():
    """With the pipeline's exclusions (2 s, and only once the camera left a keyframe's footprint), a straight run has
    no positive query, and driving back over it makes the return queries positive; a bare one-query separation
    counts every slow neighbour as a missed loop."""
    cam = CameraModel.from_dict({"fx": 500, "fy": 500, "cx": 320, "cy": 240, "width": 640, "height": 480,
                                 "camera_height": 0.5})
    n = 60
    out_and_back = np.zeros((2 * n, 3))
    out_and_back[:n, 0] = np.arange(n) * 0.05
    out_and_back[n:, 0] = out_and_back[:n, 0][::-1]
    none = np.zeros(0, int)
    loops = LoopTable(query=none, match=none, global_score=np.zeros(0), local_score=np.zeros(0),
                      probability=np.zeros(0), accepted=np.zeros(0, bool), inlier=None)
    q, t = np.arange(2 * n), np.arange(2 * n) * 0.5
    bare = loop_precision_recall(cam, out_and_back[:n], loops, queried=q[:n])
    assert bare["positive_queries"] == n - 1
    kw = dict(stamps=t, min_seconds=2.0, after_leaving=True)
    assert loop_precision_recall(cam, out_and_back[:n], loops, queried=q[:n], **kw)["positive_queries"] == 0
    back = loop_precision_recall(cam, out_and_back, loops, queried=q, **kw)
    assert n // 2 < back["positive_queries"] < n
