"""The group test's disputed clusters (graph.groups.drop_false_groups, `group_disputed`): a kept cluster that one
start kept and another rejected whole is tested beyond the `group_tests` budget; a false group that ranks behind the
budget is then dropped."""
import numpy as np
import pytest

from graph import GraphParams
from graph.factors import array_from_values
from graph.groups import drop_false_groups
from graph.labels import coincidentally_true
from graph.robust import _prepare, robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps


def _two_groups(seed: int):
    """Two laps of a square; two groups of ten mutually consistent false loops, each claiming a side of the first
    lap is the side two further on."""
    side = 30
    truth = square_laps(2, side)
    data, _ = noisy_graph(truth, np.random.default_rng(seed), loop_every=4)
    info = data.information[data.is_loop][0]
    k = np.arange(10)
    n_true = data.num_loops
    for i0, j0 in ((2, 2 * side + 2), (side + 5, 3 * side + 5)):
        data = data.append_edges(data.node_ids[j0 + k], data.node_ids[i0 + k], np.zeros((10, 3)),
                                 np.broadcast_to(info, (10, 3, 3)), True, np.full(10, np.nan))
    false = np.zeros(data.num_loops, bool)
    false[n_true:] = True
    return data, truth, false


def _group_test(disputed: bool):
    data, truth, false = _two_groups(0)
    # a budget of one cluster: one of the two groups ranks behind it
    p = GraphParams().replace(robust={"group_tests": 1})
    cs, c2 = _prepare(data, p)
    inlier = np.ones(data.num_loops, bool)
    values, _ = cs.lm(cs.built.graph(inlier), cs.odometry_values, p.solver.lm_max_iterations)
    v, kept, _ = drop_false_groups(data, cs.built, cs.base_graph, values, inlier, c2, cs.scale, cs.method, p, [],
                                   cs.stated, [inlier, ~false] if disputed else None)
    return false, kept, ate(truth, array_from_values(2, v, data.num_nodes))


def test_a_disputed_false_group_behind_the_budget_is_dropped():
    false, kept, err = _group_test(disputed=True)
    assert not kept[false].any()
    assert kept[~false].all()
    assert err < 0.5


def test_without_disputes_the_budget_bounds_the_test():
    false, kept, err = _group_test(disputed=False)
    assert kept[false].sum() == 10          # the group behind the budget stays, the map bent to it
    assert err > 5.0


def test_manhattan_random_grouped_10_seed_1(manhattan):
    # (the setting is off by default: it breaks ringCity random-grouped rows, docs/graph.md) a reporting draw: the odometry start kept part of a false group (1845.. -> 2508..), 11th in the group test's
    # order, and won; 20.8 m, 21 true loops dropped without the disputed clusters
    from vslam.bench.graph_outliers import add_false_loops
    data, truth = manhattan
    bad, false = add_false_loops(data, "random-grouped", 0.1, 1)
    res = robust_solve(bad, GraphParams().replace(robust={"group_disputed": True}))
    assert not res.loop_inlier[false & ~coincidentally_true(bad, truth)].any()
    assert res.loop_inlier[~false].all()
    assert ate(truth, res.poses) < 0.85


@pytest.mark.parametrize("seed", [0, 1])
def test_clean_two_laps_unchanged(seed):
    clean, _ = noisy_graph(square_laps(2, 30), np.random.default_rng(seed), loop_every=4)
    on = robust_solve(clean, GraphParams().replace(robust={"group_disputed": True}))
    off = robust_solve(clean, GraphParams().replace(robust={"group_disputed": False}))
    assert on.loop_inlier.all()
    assert np.array_equal(on.loop_inlier, off.loop_inlier)
    assert np.allclose(on.poses, off.poses)
