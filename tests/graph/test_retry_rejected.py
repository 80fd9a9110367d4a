"""The re-try of supported clusters rejected whole (graph.groups.retry_rejected): a true revisit left out comes
back when the group-level objective is lower with it; a consistent false group left out stays out."""
import numpy as np

from graph import GraphParams
from graph.factors import array_from_values
from graph.groups import retry_rejected
from graph.robust import _prepare
from tests.graph.synth import ate
from tests.graph.test_false_groups import _grouped


def _retry(kept_false: bool, kept_true: bool, budget: int = 3, forecast: bool = True):
    data, truth, false, _ = _grouped(2, 30, 4, 1, 0)
    p = GraphParams().replace(robust={"retry_clusters": budget, "retry_forecast": forecast})
    cs, c2 = _prepare(data, p)
    inlier = (false & kept_false) | (~false & kept_true & cs.cand)
    values, _ = cs.lm(cs.built.graph(inlier), cs.odometry_values, p.solver.lm_max_iterations)
    v, new, _ = retry_rejected(data, cs.built, cs.base_graph, values, inlier, cs.cand, c2, cs.scale, p, [])
    err = (ate(truth, array_from_values(2, values, data.num_nodes)), ate(truth, array_from_values(2, v, data.num_nodes)))
    return false, cs.cand, inlier, new, err


def test_a_true_revisit_rejected_whole_comes_back():
    false, cand, _, new, (before, after) = _retry(kept_false=False, kept_true=False)
    assert new[~false & cand].all()
    assert not new[false].any()
    assert after < 0.2 * before


def test_a_false_group_rejected_whole_stays_out():
    false, _, inlier, new, (before, after) = _retry(kept_false=False, kept_true=True)
    assert np.array_equal(new, inlier)
    assert after == before


def test_off_changes_nothing():
    false, _, inlier, new, (before, after) = _retry(kept_false=False, kept_true=False, budget=0)
    assert np.array_equal(new, inlier)
    assert after == before


def test_the_forecast_on_the_marginal_keeps_the_outcome():
    # retry_forecast skips the whole-graph re-try of a cluster none of whose loops survives it on the marginal of
    # the solved map: the true revisit still comes back, the false group still stays out, as without the forecast
    for kept_true in (False, True):
        on = _retry(kept_false=False, kept_true=kept_true)
        off = _retry(kept_false=False, kept_true=kept_true, forecast=False)
        assert np.array_equal(on[3], off[3])
        assert abs(on[4][1] - off[4][1]) < 1e-6
