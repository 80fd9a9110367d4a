"""The two cuts of the reduced graph's cost (graph.cluster_start): a representative whose GNC weight is below
`gnc_weights_tol` leaves the step's graph (`cluster_zero_weights`), and the second reduced GNC is skipped where the
first leaves every cluster decided at its map (`cluster_decided_alone`). Each keeps the labels: the same loops with
it on and off, on graphs with groups of consistent false loops (Vertigo's random-grouped policy) and on clean ones,
on the cluster path (forced by `solver.direct_max_cost`: every graph filling in, or only the candidates with the
false groups) and on the ordinary one."""
import numpy as np
import pytest

from graph import GraphParams
from graph.cluster_start import representatives, undecided_share
from graph.robust import _prepare, robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops

# between the fill estimate of the true candidates (<= 3.7e5 flops on these graphs) and that of every candidate with
# the false groups (>= 1.3e6): the candidates fill in, a decision keeping only true clusters does not
SPLIT_COST = 8e5


def _grouped(laps: int, side: int, seed: int, fraction: float = 0.5):
    truth = square_laps(laps, side)
    data, _ = noisy_graph(truth, np.random.default_rng(seed))
    bad, false = add_false_loops(data, "random-grouped", fraction, seed)
    return bad, false, truth


@pytest.mark.parametrize("laps,side,seed", [(4, 12, 1), (3, 20, 3), (4, 15, 2)])
@pytest.mark.parametrize("limit", [0.0, SPLIT_COST, None])
@pytest.mark.parametrize("setting", ["cluster_zero_weights", "cluster_decided_alone"])
def test_same_labels_with_the_cut_on_and_off(laps, side, seed, limit, setting):
    bad, false, truth = _grouped(laps, side, seed)
    params = GraphParams() if limit is None else GraphParams().replace(solver={"direct_max_cost": limit})
    on = robust_solve(bad, params.replace(robust={setting: True}))
    off = robust_solve(bad, params.replace(robust={setting: False}))
    assert np.array_equal(on.loop_inlier, off.loop_inlier)
    assert on.loop_inlier[~false].all() and not on.loop_inlier[false].any()
    assert abs(ate(truth, on.poses) - ate(truth, off.poses)) <= 1e-6


def test_same_labels_where_the_first_reduced_decision_leaves_every_cluster_decided():
    # five representatives a cluster: the reduced decision from the odometry chain fits every kept cluster whole and
    # misfits every rejected one whole at its map (this draw), so the other reduced GNC is the one skipped
    bad, false, truth = _grouped(4, 12, 1)
    params = GraphParams().replace(solver={"direct_max_cost": SPLIT_COST}, robust={"cluster_representatives": 5})
    on = robust_solve(bad, params.replace(robust={"cluster_decided_alone": True}))
    off = robust_solve(bad, params.replace(robust={"cluster_decided_alone": False}))
    assert np.array_equal(on.loop_inlier, off.loop_inlier)
    assert on.loop_inlier[~false].all() and not on.loop_inlier[false].any()
    assert abs(ate(truth, on.poses) - ate(truth, off.poses)) <= 1e-6


@pytest.mark.parametrize("setting", ["cluster_zero_weights", "cluster_decided_alone"])
def test_clean_graph_unchanged_by_the_cut(setting):
    truth = square_laps(3, 15)
    data, _ = noisy_graph(truth, np.random.default_rng(4))
    params = GraphParams().replace(solver={"direct_max_cost": 0.0})
    on = robust_solve(data, params.replace(robust={setting: True}))
    off = robust_solve(data, params.replace(robust={setting: False}))
    assert on.loop_inlier.all() and off.loop_inlier.all()
    assert np.allclose(on.poses, off.poses, atol=1e-6)


def test_undecided_share_counts_split_clusters():
    bad, false, _ = _grouped(4, 12, 1)
    cs, c2 = _prepare(bad, GraphParams())
    _, _, _, label = representatives(cs, 1)
    cand = np.flatnonzero(cs.cand)
    n = int(label.max()) + 1
    # the map of the true loops, the decision keeping the clusters without false loops: every cluster decided
    truth_map, _ = cs.lm(cs.built.graph(~false), cs.odometry_values, 100)
    true_cl = np.flatnonzero(np.bincount(label, weights=false[cand].astype(float), minlength=n) == 0)
    assert undecided_share(cs, c2, truth_map, label, true_cl) == 0.0
    # one true cluster rejected: it fits whole there, so it is undecided; one with a loop misfitting, likewise
    assert undecided_share(cs, c2, truth_map, label, true_cl[1:]) == pytest.approx(1.0 / n)
    sizes = np.bincount(label, minlength=n)
    big = true_cl[np.argmax(sizes[true_cl])]
    assert sizes[big] >= 2
    strained = c2.copy()
    strained[cand[np.flatnonzero(label == big)[0]]] = 0.0
    assert undecided_share(cs, strained, truth_map, label, true_cl) == pytest.approx(1.0 / n)
