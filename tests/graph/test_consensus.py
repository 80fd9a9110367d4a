"""The default robust mode (local cycle consensus + GNC-TLS) and the RobustPoseGraph front door."""
import numpy as np
import pytest

from graph import GraphParams, RobustPoseGraph, inject_false_loops, loop_scores, optimize
from graph.support import clusters, loop_support
from odometry.shared.poses import between, integrate
from tests.graph.synth import ate, noisy_graph, square_laps


def drifted(bias: float, seed: int = 3):
    """Three laps of a square with a constant heading bias on every odometry step (gyro-like drift)."""
    truth = square_laps(laps=3, side=8)
    data, truth = noisy_graph(truth, np.random.default_rng(seed), sigma_xy=0.01, sigma_th=0.002)
    odo = ~data.is_loop
    data.measurements[odo, 2] += bias
    return data, truth


def test_true_loops_kept_under_large_heading_drift():
    data, truth = drifted(bias=0.02)              # 0.02 rad per step: ~110 degrees of heading error after 3 laps
    plain = optimize(data, GraphParams.preset("least_squares"))
    res = optimize(data)
    assert ate(truth, integrate(data.measurements[~data.is_loop])) > 0.3     # the drift is large ...
    assert res.loop_inlier.all()                  # ... and every true loop is kept
    assert ate(truth, res.poses) <= 1.01 * ate(truth, plain.poses) + 1e-6
    old = optimize(data, GraphParams().replace(robust="gnc"))
    assert not old.loop_inlier.all()              # the arrival gate rejected true loops here (issue 14)


@pytest.mark.parametrize("fraction", [0.3, 0.5])
def test_random_false_loops_rejected_and_clean_map_kept(fraction):
    data, truth = drifted(bias=0.01)
    clean = optimize(data, GraphParams.preset("least_squares"))
    dd, injected = inject_false_loops(data, fraction, seed=5)
    res = optimize(dd)
    sc = loop_scores(res.loop_inlier, injected[dd.is_loop])
    assert sc.recall == 1.0 and sc.false_rejected >= 0.99
    assert ate(clean.poses, res.poses) <= 0.01


def test_support_pairs_and_clusters():
    data, _ = drifted(bias=0.0)
    p, q, r2 = loop_support(data, window=10, threshold=11.34)
    assert len(p) > 0 and np.all(r2 <= 11.34)
    lab = clusters(data.num_loops, p, q)
    assert len(lab) == data.num_loops and lab.max() < data.num_loops
    dd, injected = inject_false_loops(data, 0.5, seed=2)
    p2, q2, _ = loop_support(dd, window=10, threshold=11.34)
    supported = np.zeros(dd.num_loops, bool)
    supported[p2] = supported[q2] = True
    assert supported[~injected[dd.is_loop]].mean() > 0.9      # true loops support each other
    assert supported[injected[dd.is_loop]].mean() < 0.1       # random false loops have no support


@pytest.mark.parametrize("strategy", ["lm", "isam2"])
def test_front_door(strategy):
    data, truth = drifted(bias=0.01)
    g = RobustPoseGraph(2, strategy=strategy)
    a, b = data.edge_index_pairs()
    for k, nid in enumerate(data.node_ids):
        g.add_node(int(nid), data.poses[k] if k == 0 else None)
    ids0, poses0 = g.estimate()
    assert len(ids0) == data.num_nodes
    for e in range(data.num_edges):
        cov = np.linalg.inv(data.information[e])
        if data.is_loop[e]:
            g.add_loop(int(data.edge_from[e]), int(data.edge_to[e]), data.measurements[e], cov)
        else:
            g.add_odometry(int(data.edge_from[e]), int(data.edge_to[e]), data.measurements[e], cov)
    ids, poses = g.update()
    assert len(ids) == data.num_nodes and np.all(np.isfinite(poses))
    res = g.result()
    assert res.loop_inlier.all() and g.loop_inliers().all()
    assert ate(truth, res.poses) < 0.2
    np.testing.assert_allclose(g.estimate()[1], res.poses)
    assert g.to_data().num_loops == data.num_loops
    assert between(res.poses[:1], res.poses[1:2]).shape == (1, 3)
