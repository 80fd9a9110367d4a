"""Regression: a drifted odometry chain from our own pipeline with ONE true loop closure (tests/graph/data).

With a single loop there is no population of arrival residuals for the gate to calibrate on, and the loop's stated
information is very tight (1e8 on translation) against a chain that drifted ~1 cm: the robust paths must keep it.
"""
from pathlib import Path

import numpy as np
import pytest

from graph import GraphParams, IncrementalPoseGraph, optimize, read_graph

DATA = Path(__file__).parent / "data" / "single_true_loop.g2o"


@pytest.fixture(scope="module")
def data():
    d = read_graph(DATA)
    assert d.num_loops == 1
    return d


def _loop_error(d, poses) -> float:
    """Translation residual of the loop edge at `poses` (metres)."""
    e = int(np.flatnonzero(d.is_loop)[0])
    a, b = d.edge_index_pairs()
    xa, xb = poses[a[e]], poses[b[e]]
    c, s = np.cos(xa[2]), np.sin(xa[2])
    rel = np.array([c * (xb[0] - xa[0]) + s * (xb[1] - xa[1]), -s * (xb[0] - xa[0]) + c * (xb[1] - xa[1])])
    return float(np.linalg.norm(rel - d.measurements[e, :2]))


@pytest.mark.parametrize("robust", ["gnc", "huber", "cauchy"])
def test_batch_robust_keeps_the_single_true_loop(data, robust):
    res = optimize(data, GraphParams(), robust=robust)
    assert res.loop_inlier.tolist() == [True]
    assert _loop_error(data, data.poses) > 5e-3            # the drift the loop has to close ...
    assert _loop_error(data, res.poses) < 1e-3             # ... is closed


def test_isam2_pass_keeps_the_single_true_loop(data):
    res = optimize(data, GraphParams(), solver="isam2")
    assert res.loop_inlier.tolist() == [True]
    assert _loop_error(data, res.poses) < 1e-3


@pytest.mark.parametrize("probability", [None, 0.5])
def test_online_graph_as_the_pipeline_feeds_it_keeps_the_single_true_loop(data, probability):
    """Nodes with odometry guesses, one update() per node, the loop with its P(loop); then result()."""
    a, b = data.edge_index_pairs()
    newer = np.maximum(a, b)
    inc = IncrementalPoseGraph(2, GraphParams().replace(incremental={"batch_nodes": 1}))
    for k in range(data.num_nodes):
        inc.add_node(int(data.node_ids[k]), data.poses[k])
        for e in np.flatnonzero(newer == k).tolist():
            if data.is_loop[e]:
                assert inc.add_loop(data.edge_from[e], data.edge_to[e], data.measurements[e],
                                    information=data.information[e], probability=probability) == 0
            else:
                inc.add_odometry(data.edge_from[e], data.edge_to[e], data.measurements[e],
                                 information=data.information[e])
        inc.update()
    unclassified = inc.result(classify=False)
    assert unclassified.loop_inlier.tolist() == [True]
    res = inc.result(classify=True)
    assert res.loop_inlier.tolist() == [True] and inc.loop_inliers().tolist() == [True]
    assert _loop_error(data, res.poses) < 1e-3
