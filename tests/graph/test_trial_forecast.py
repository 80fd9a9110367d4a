"""`robust.trial_forecast`: the joint trial's GNC run first on the marginal of the solved map on the tried loops'
end poses (graph.reduced); the whole-graph trial is not run when that keeps none. Same labels either way."""
import numpy as np

from graph import GraphParams, optimize
from graph.reduced import reduced_gnc
from tests.graph.test_consensus_trial import lone_loop_graph


def _both(data):
    on = optimize(data, GraphParams().replace(robust={"trial_forecast": True}))
    off = optimize(data, GraphParams().replace(robust={"trial_forecast": False}))
    return on, off


def test_forecast_keeps_the_lone_true_loop_the_trial_is_for():
    # the lone loop closing lap 3 fits only once the map moves to it: the forecast keeps it, so the trial runs
    _, dd, false, _ = lone_loop_graph(bias=0.001)
    on, off = _both(dd)
    assert np.array_equal(on.loop_inlier, off.loop_inlier)
    assert on.loop_inlier[~false].all() and not on.loop_inlier[false].any()
    assert np.max(np.abs(on.poses - off.poses)) < 1e-6


def test_forecast_without_a_loop_to_add_gives_the_labels_of_the_whole_graph_trial():
    # the same graph without its lone true loop: every unsupported loop is false, none is added either way
    _, dd, false, _ = lone_loop_graph(bias=0.001)
    a, b = dd.edge_index_pairs()
    true_loops = np.flatnonzero(dd.is_loop)[~false]
    lone = true_loops[np.maximum(a[true_loops], b[true_loops]) >= 64]      # the one loop of lap 3
    assert len(lone) == 1
    keep = np.ones(dd.num_edges, bool)
    keep[lone] = False
    data = dd.with_edges(keep)
    false = false[np.flatnonzero(dd.is_loop) != lone[0]]
    on, off = _both(data)
    assert np.array_equal(on.loop_inlier, off.loop_inlier)
    assert on.loop_inlier[~false].all() and not on.loop_inlier[false].any()
    assert np.max(np.abs(on.poses - off.poses)) < 1e-3


def test_reduced_gnc_keeps_a_consistent_loop_and_rejects_a_false_one():
    import gtsam

    # a chain of 20 poses 1 m apart along x; the known factors: anchor + odometry
    noise = gtsam.noiseModel.Isotropic.Sigma(3, 0.01)
    known = [gtsam.PriorFactorPose2(0, gtsam.Pose2(), noise)]
    values = gtsam.Values()
    for k in range(20):
        values.insert(k, gtsam.Pose2(float(k), 0.0, 0.0))
        if k:
            known.append(gtsam.BetweenFactorPose2(k - 1, k, gtsam.Pose2(1.0, 0.0, 0.0), noise))
    good = gtsam.BetweenFactorPose2(2, 15, gtsam.Pose2(13.0, 0.0, 0.0), noise)
    bad = gtsam.BetweenFactorPose2(4, 11, gtsam.Pose2(0.0, 3.0, 1.0), noise)
    kept = reduced_gnc(known, values, [good, bad], np.full(2, 11.34), 2, GraphParams())
    assert kept.tolist() == [True, False]
