"""The disputed clusters judged jointly (graph.disputed): kept clusters that some start rejected whole leave at
once and are offered back one by one; false groups stay out, true clusters come back."""
import numpy as np
import pytest

from graph import GraphParams
from graph.disputed import judge_disputed
from graph.factors import array_from_values
from graph.labels import coincidentally_true
from graph.robust import _prepare, robust_solve
from graph.support import revisits
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


def _bent(seed: int):
    """The two-group square with every loop kept, on the map the groups bent."""
    data, truth, false = _two_groups(seed)
    p = GraphParams()
    cs, c2 = _prepare(data, p)
    inlier = np.ones(data.num_loops, bool)
    values, _ = cs.lm(cs.built.graph(inlier), cs.odometry_values, p.solver.lm_max_iterations)
    return data, truth, false, p, cs, c2, inlier, values


def _judge(seed: int, also_true: bool):
    """The starts: every loop kept, and a start that rejected both groups (and, with `also_true`, a true revisit
    cluster as well)."""
    data, truth, false, p, cs, c2, inlier, values = _bent(seed)
    other = ~false
    if also_true:
        component = revisits(data, p.robust.support_window, ~false)
        labels, counts = np.unique(component[~false], return_counts=True)
        other &= component != labels[np.argmax(counts)]       # the largest true revisit cluster, rejected whole
    v, kept, _ = judge_disputed(data, cs.built, cs.base_graph, values, inlier, c2, cs.scale, cs.method, p, [],
                                [inlier, other], cs.stated)
    return false, kept, ate(truth, array_from_values(2, v, data.num_nodes)), ate(
        truth, array_from_values(2, values, data.num_nodes))


@pytest.mark.parametrize("seed", [0, 3, 4])
@pytest.mark.parametrize("also_true", [False, True])
def test_false_groups_out_and_true_clusters_back(seed, also_true):
    false, kept, err, before = _judge(seed, also_true)
    assert before > 5.0                        # the map was bent by the groups
    assert not kept[false].any()
    assert kept[~false].all()
    assert err < 0.5


def test_no_disagreement_between_starts_leaves_the_decision():
    data, _, _, p, cs, c2, inlier, values = _bent(0)
    v, kept, _ = judge_disputed(data, cs.built, cs.base_graph, values, inlier, c2, cs.scale, cs.method, p, [],
                                [inlier, inlier], cs.stated)
    assert v is values and np.array_equal(kept, inlier)


def test_manhattan_random_grouped_10_seed_1(manhattan):
    # a reporting draw: the odometry start kept part of a false group (1845.. -> 2508..), 11th in the group test's
    # order, and won; 22 m with 21 true loops dropped without the joint test
    from vslam.bench.graph_outliers import add_false_loops
    data, truth = manhattan
    bad, false = add_false_loops(data, "random-grouped", 0.1, 1)
    res = robust_solve(bad, GraphParams())
    assert not res.loop_inlier[false & ~coincidentally_true(bad, truth)].any()
    assert res.loop_inlier[~false].all()
    assert ate(truth, res.poses) < 0.85
