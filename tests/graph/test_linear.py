"""The linear solver choice of batch LM (graph.linear): direct Cholesky below the estimated fill-in cost, PCG above;
either way the solve reaches the same optimum."""
from __future__ import annotations

import numpy as np

from graph import GraphParams
from graph.linear import fill_cost
from graph.optimizer import optimize
from odometry.shared.poses import between, compose
from tests.graph.synth import ate, noisy_graph, square_laps


def _long_range(seed: int = 5, extra: int = 60):
    """Four laps of a square (revisit loops one lap apart) plus `extra` true loops between random pose pairs."""
    truth = square_laps(laps=4, side=10)
    rng = np.random.default_rng(seed)
    data, _ = noisy_graph(truth, rng, sigma_xy=0.05, sigma_th=0.02)
    n = len(truth)
    i = rng.integers(0, n, extra)
    j = (i + rng.integers(20, n - 20, extra)) % n
    z = compose(between(truth[j], truth[i]), rng.normal(0.0, [0.05, 0.05, 0.02], size=(extra, 3)))
    info = np.linalg.inv(np.diag([0.05 ** 2, 0.05 ** 2, 0.02 ** 2]))
    out = data.append_edges(data.node_ids[j], data.node_ids[i], z, np.broadcast_to(info, (extra, 3, 3)),
                            np.ones(extra, bool), np.full(extra, np.nan))
    return out, truth


def _chain_and_far(n: int, far_count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Node pairs of an n-node chain, and up to `far_count` random long-range pairs (no self-pair)."""
    chain = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    far = np.random.default_rng(seed).integers(0, n, (far_count, 2))
    return chain, far[far[:, 0] != far[:, 1]]


def test_fill_cost_grows_with_long_range_loops():
    n = 400
    chain, far = _chain_and_far(n, 200, 0)
    c_chain = fill_cost(chain, 2)
    # a chain eliminates with one neighbour per node: ~ n x 27 x 2^2
    assert c_chain <= 27 * 4 * n
    assert fill_cost(np.vstack([chain, far]), 2) > 20 * c_chain
    assert fill_cost(chain, 3) > c_chain          # 6-dof blocks cost more than 3-dof ones


def test_default_limit_changes_nothing_on_a_small_graph():
    data, _ = _long_range()
    a = optimize(data, GraphParams())
    b = optimize(data, GraphParams().replace(solver={"direct_max_cost": float("inf")}))
    assert np.array_equal(a.loop_inlier, b.loop_inlier)
    assert np.array_equal(a.poses, b.poses)


def test_iterative_solve_reaches_the_direct_optimum():
    data, truth = _long_range()
    for robust in ("none", "consensus"):
        direct = optimize(data, GraphParams(robust=robust).replace(solver={"direct_max_cost": float("inf")}))
        pcg = optimize(data, GraphParams(robust=robust).replace(solver={"direct_max_cost": 0.0}))
        assert np.array_equal(direct.loop_inlier, pcg.loop_inlier)
        assert direct.loop_inlier.all()
        # same optimum: the maps agree far below their error against the truth
        assert ate(direct.poses, pcg.poses) < 1e-3
        assert abs(ate(truth, pcg.poses) - ate(truth, direct.poses)) < 1e-3
        assert abs(pcg.final_cost - direct.final_cost) <= 1e-3 * direct.final_cost


def test_capped_fill_cost_is_exact_below_its_cap_and_above_it_once_passed():
    chain, far = _chain_and_far(400, 300, 1)
    for pairs in (chain, np.vstack([chain, far])):
        full = fill_cost(pairs, 2)
        assert fill_cost(pairs, 2, cap=2 * full) == full        # never passed: the whole elimination, same sum
        low = full / 1000
        capped = fill_cost(pairs, 2, cap=low)
        assert low < capped <= full                               # stopped once past the cap: a lower bound


def test_the_scope_verdict_is_the_whole_graphs_whether_a_subgraph_is_estimated_first_or_not():
    from graph.linear import narrow, solver_scope

    data, _ = _long_range(extra=120)
    a, b = data.edge_index_pairs()
    pairs = np.column_stack([a, b])
    sub = pairs[:-60]
    whole_cost, sub_cost = fill_cost(pairs, 2), fill_cost(sub, 2)
    assert sub_cost < whole_cost
    for limit in (0.5 * sub_cost, 0.5 * (sub_cost + whole_cost), 2.0 * whole_cost):
        params = GraphParams().replace(solver={"direct_max_cost": limit})
        with solver_scope(pairs, 2, params) as scope:
            with narrow(lambda: sub):
                pass
            assert scope.all_direct == (whole_cost <= limit)
        with solver_scope(pairs, 2, params) as scope:
            assert scope.all_direct == (whole_cost <= limit)
