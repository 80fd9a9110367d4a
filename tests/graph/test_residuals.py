"""The vectorised loop residuals (graph.residuals) against gtsam's own factor errors, and their use in the robust
solve's group test (one joint screen instead of one solve per cluster)."""
import numpy as np

from graph import GraphParams
from graph.batch import build
from graph.factors import squared_residuals, values_from_array
from graph.params import LoopWeighting
from graph.residuals import LoopResiduals
from graph.robust import robust_solve
from tests.graph.synth import noisy_graph, square_laps


def _graph(seed: int = 0):
    data, truth = noisy_graph(square_laps(3, 8), np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 1)
    # loops of every kind of error: large rotations (past +-pi), tiny ones, correlated information
    k = data.num_loops
    src = data.node_ids[rng.integers(0, data.num_nodes, 40)]
    dst = data.node_ids[rng.integers(0, data.num_nodes, 40)]
    z = np.column_stack([rng.normal(0, 5, (40, 2)), rng.uniform(-np.pi, np.pi, 40)])
    a = rng.normal(size=(40, 3, 3))
    info = a @ np.swapaxes(a, 1, 2) + 0.1 * np.eye(3)
    out = data.append_edges(src, dst, z, info, True, rng.uniform(0.05, 0.95, 40))
    return out, k


def test_planar_residuals_equal_gtsam_factor_errors():
    data, _ = _graph()
    rng = np.random.default_rng(3)
    for weighting in (LoopWeighting.THRESHOLD, LoopWeighting.INFORMATION):
        built = build(data, GraphParams().replace(robust={"loop_weighting": weighting}))
        assert built.residuals is not None and built.residuals.z is not None      # the vectorised path
        poses = data.poses.copy()
        poses[:, :2] += rng.normal(0, 2.0, (len(poses), 2))
        poses[:, 2] = rng.uniform(-np.pi, np.pi, len(poses))
        poses[::7, 2] = poses[1::7, 2][: len(poses[::7])] if len(poses) % 7 == 0 else poses[::7, 2]
        for p in (poses, data.poses):
            v = values_from_array(2, p)
            want = squared_residuals(built.loops, v)
            np.testing.assert_allclose(built.r2(v), want, rtol=1e-9, atol=1e-12)
            keep = rng.random(len(built.loops)) < 0.5
            np.testing.assert_allclose(built.subset(keep).r2(v), want[keep], rtol=1e-9, atol=1e-12)


def test_zero_rotation_error_branch():
    data, _ = _graph()
    built = build(data, GraphParams())
    # at the poses the measurements were chained from, odometry-like loops have near-zero rotation error
    v = values_from_array(2, data.poses)
    r = LoopResiduals.of_edges(data, built.loop_idx, built.a, built.b, built.loops)(v)
    np.testing.assert_allclose(r, squared_residuals(built.loops, v), rtol=1e-9, atol=1e-12)


def _runs_of_loops(seed: int):
    """Three laps of a square, loops only where the newer pose is in the first 5 of every 20 places: 60 separate
    revisit clusters (graph.support.revisits), each place seen three times; a map that holds without any ten of
    its clusters, as the densely looped public graphs do (city10000, w10000)."""
    data, truth = noisy_graph(square_laps(3, 100), np.random.default_rng(seed))
    a, b = data.edge_index_pairs()
    keep = ~data.is_loop | (np.maximum(a, b) % 20 < 5)
    return data.with_edges(keep), truth


def test_joint_screen_passes_every_true_cluster_of_a_clean_graph_with_the_same_result():
    data, truth = _runs_of_loops(1)
    on = robust_solve(data, GraphParams())
    off = robust_solve(data, GraphParams().replace(robust={"group_joint_screen": False}))
    # the outcome is the one of screening each cluster on its own
    assert np.array_equal(on.loop_inlier, off.loop_inlier) and on.loop_inlier.all()
    np.testing.assert_allclose(on.poses, off.poses, atol=1e-6)
