"""Loop ground truth (J >= r) and the learned model: fit, thresholds, save/load."""
import json

import numpy as np
import pytest

from loops.cdvs.groundtruth import loop_labels, pair_overlaps
from loops.cdvs.model import LoopModel, fit_curve, isotonic
from odometry.shared.camera import CameraModel

CAM = CameraModel(640, 480, 500.0, 500.0, 319.5, 239.5, camera_height=0.5)  # footprint 0.64 m x 0.48 m


def test_j_ground_truth_from_poses():
    poses = np.array([[0, 0, 0], [0, 0, 0], [0.16, 0, 0], [0.32, 0, 0], [2.0, 0, 0], [0, 0, np.pi]], float)
    pairs = np.array([[0, 1], [0, 2], [0, 3], [0, 4], [0, 5]])
    J, loop = loop_labels(CAM, poses, pairs, r=0.33)
    assert J[0] == pytest.approx(1.0)
    assert J[1] == pytest.approx(0.48 / 0.80, abs=0.01)      # shift by a quarter: (0.48 x 0.48) / (0.80 x 0.48)
    assert J[2] == pytest.approx(0.32 / 0.96, abs=0.01)      # half: 1/3
    assert J[3] == 0.0
    assert J[4] == pytest.approx(1.0, abs=0.02)              # turning on the spot keeps the same floor (centred)
    assert loop.tolist() == [True, True, True, False, True]
    assert not loop_labels(CAM, poses, pairs[2:3], r=0.34)[1][0]   # r is configurable
    assert pair_overlaps(CAM, poses, np.zeros((0, 2))).shape == (0,)


def test_isotonic_is_monotone_and_weighted():
    y = np.array([0.0, 0.5, 0.2, 0.9, 0.0, 1.0, 1.0])
    w = np.array([5, 2, 2, 1, 0, 3, 0])
    p = isotonic(y, w)
    assert np.all(np.diff(p) >= -1e-12)
    assert p[-1] == 1.0 and p[4] == p[5]     # empty bins take their neighbours' value


def test_fit_curve_threshold_is_the_lowest_certain_score():
    rng = np.random.default_rng(0)
    neg = rng.uniform(0, 4, 300)
    pos = np.concatenate([rng.uniform(2, 30, 300), rng.uniform(0, 2, 20)])
    s = np.concatenate([neg, pos])
    y = np.concatenate([np.zeros(300, bool), np.ones(320, bool)])
    c = fit_curve(3, s, y)
    assert c.threshold > neg.max() and c.threshold < 5.0
    assert np.all(np.diff(c.probability) >= -1e-12)
    assert c.prob(50.0) == 1.0 and c.prob(0.1) < 0.2
    assert fit_curve(3, neg, np.zeros(300, bool)).threshold == np.inf   # never certain without positives


def test_model_save_load_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    m = LoopModel(0.33, provenance={"note": "test"}, min_overlap=0.38)
    for mode in (1, 4):
        s = rng.uniform(0, 20, 200)
        m.curves[mode] = fit_curve(mode, s, s + rng.normal(0, 3, 200) > 10)
    path = tmp_path / "model.json"
    m.save(path)
    back = LoopModel.load(path)
    assert back.overlap_threshold == 0.33 and back.provenance == {"note": "test"} and back.min_overlap == 0.38
    for mode in (1, 4):
        assert back.threshold(mode) == pytest.approx(m.threshold(mode))
        for s in (0.0, 3.3, 9.9, 15.0, 1e6):
            assert back.probability(mode, s) == pytest.approx(m.probability(mode, s), abs=1e-6)
    with pytest.raises(KeyError, match="mode 2"):
        back.threshold(2)


@pytest.mark.parametrize("text,msg", [("{", "invalid JSON"), ('{"format": "x"}', "not a loop model"),
                                      ('{"format": "vslam-loop-model", "version": 99}', "version"),
                                      ('{"format": "vslam-loop-model", "version": 1, "min_overlap": 2}', "min_overlap"),
                                      ('{"format": "vslam-loop-model", "version": 1, "modes": {"3": {"edges": [0, 1]}}}',
                                       "mode 3")])
def test_bad_model_files_raise_clear_errors(tmp_path, text, msg):
    p = tmp_path / "bad.json"
    p.write_text(text)
    with pytest.raises(ValueError, match=msg) as e:
        LoopModel.load(p)
    assert "bad.json" in str(e.value)


def test_default_model_ships_all_modes():
    m = LoopModel.default()
    assert sorted(m.curves) == [1, 2, 3, 4, 5, 6]
    for mode in range(1, 7):
        assert m.probability(mode, 1e6) == 1.0
        assert 0 < m.threshold(mode) < 1e3
    assert json.dumps(m.to_dict())


def test_fit_with_min_overlap_uses_only_pairs_whose_transform_overlaps_enough():
    from loops.cdvs.loop_training import PairScores, fit_loop_model

    rng = np.random.default_rng(2)
    n = 400
    J = rng.uniform(0, 1, n)
    local = 40 * J + rng.normal(0, 2, n)              # near misses (J just under r) score as high as true loops
    est = J + rng.normal(0, 0.01, n)                  # the verified transform knows the overlap
    ps = PairScores(np.zeros((n, 2), int), J, {4: local}, {4: np.zeros(n)}, {4: est})
    plain = fit_loop_model([ps], 0.33)
    gated = fit_loop_model([ps], 0.33, min_overlap=0.38)
    assert gated.min_overlap == 0.38 and plain.min_overlap is None
    assert gated.threshold(4) < plain.threshold(4)
    acc = (local >= gated.threshold(4)) & (est >= 0.38)
    assert not np.any(acc & (J < 0.33))               # still no false loop
