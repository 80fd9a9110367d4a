"""The clusters decided on a reduced graph (graph.cluster_start): where every solve over the candidate loops would
fill in (here forced by `solver.direct_max_cost` 0: every graph counts as one that fills in), groups of consistent
false loops (Vertigo's random-grouped policy) are rejected and every true loop kept, as with the GNC starts."""
import numpy as np
import pytest

from graph import GraphParams
from graph.robust import robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops


@pytest.mark.parametrize("laps,side,seed", [(4, 12, 1), (3, 20, 3)])
def test_false_groups_rejected_when_the_candidates_fill_in(laps, side, seed):
    truth = square_laps(laps, side)
    data, _ = noisy_graph(truth, np.random.default_rng(seed))
    bad, false = add_false_loops(data, "random-grouped", 0.5, seed)
    keep = np.ones(bad.num_edges, bool)
    keep[bad.loop_edges()[false]] = False
    clean = robust_solve(bad.with_edges(keep), GraphParams())
    costly = GraphParams().replace(solver={"direct_max_cost": 0.0})
    # the reduced graph's own solves direct, by PCG (`cluster_direct_max_cost` 0), with three loops standing for each
    # cluster, and the GNC starts instead
    for robust in ({}, {"cluster_direct_max_cost": 0.0}, {"cluster_representatives": 3}, {"cluster_start": False}):
        res = robust_solve(bad, costly.replace(robust=robust))
        assert res.loop_inlier[~false].all()
        assert not res.loop_inlier[false].any()
        assert ate(truth, res.poses) <= 1.01 * ate(truth, clean.poses) + 1e-3


def test_clean_graph_unchanged_when_the_candidates_fill_in():
    truth = square_laps(3, 15)
    data, _ = noisy_graph(truth, np.random.default_rng(4))
    costly = GraphParams().replace(solver={"direct_max_cost": 0.0})
    on = robust_solve(data, costly)
    off = robust_solve(data, costly.replace(robust={"cluster_start": False}))
    assert on.loop_inlier.all() and off.loop_inlier.all()
    assert np.allclose(on.poses, off.poses, atol=1e-6)
