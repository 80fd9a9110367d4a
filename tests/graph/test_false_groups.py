"""Groups of mutually consistent false loops (Vertigo's random-grouped policy): ten loops (i+k, j+k), one claimed
relative pose, between two straight stretches. They support each other in the local cycle test and, once the map
has bent to them, each fits its own threshold; the group-level test (graph.robust) must drop them."""
import numpy as np
import pytest
from scipy.stats import chi2

from graph import GraphParams
from graph.groups import group_threshold
from graph.robust import robust_solve
from graph.support import revisits
from tests.graph.synth import ate, noisy_graph, square_laps


def _grouped(laps: int, side: int, every: int, seed: int, offset: int):
    truth = square_laps(laps, side)
    data, _ = noisy_graph(truth, np.random.default_rng(seed), loop_every=every)
    i0 = 2 + offset                                    # first side of the first lap ...
    j0 = 2 * side + 2 + offset + (4 * side if laps > 2 else 0)   # ... claimed to be the third side
    info = data.information[data.is_loop][0]
    k = np.arange(10)
    out = data.append_edges(data.node_ids[j0 + k], data.node_ids[i0 + k], np.zeros((10, 3)),
                            np.broadcast_to(info, (10, 3, 3)), True, np.full(10, np.nan))
    false = np.zeros(out.num_loops, bool)
    false[-10:] = True
    return out, truth, false, data


# each of these kept the group (or bent the map to a 15-18 m ATE) before the group test
@pytest.mark.parametrize("laps,side,every,seed,offset", [(2, 30, 4, 1, 0), (2, 30, 8, 1, 5), (3, 30, 4, 0, 5)])
def test_consistent_false_group_rejected(laps, side, every, seed, offset):
    data, truth, false, without = _grouped(laps, side, every, seed, offset)
    clean = robust_solve(without, GraphParams())
    res = robust_solve(data, GraphParams())
    assert not res.loop_inlier[false].any()
    assert res.loop_inlier[~false].all()
    assert ate(truth, res.poses) <= 1.01 * ate(truth, clean.poses) + 1e-3


def test_revisit_clusters_join_a_group_split_by_the_cycle_test():
    data, _, false, _ = _grouped(2, 30, 4, 1, 0)
    label = revisits(data, 10, np.ones(data.num_loops, bool))
    assert len(np.unique(label[false])) == 1              # one claim, one cluster
    assert not np.isin(label[false], label[~false]).any()  # not merged with the true revisits
    assert np.all(revisits(data, 10, ~false)[false] == -1)


def test_group_threshold_is_the_chi_square_of_its_total_dof():
    p = GraphParams().replace(robust={"group_margin_once": False})
    assert group_threshold(np.full(10, np.nan), 3, 2.0, p) == pytest.approx(2.0 * chi2.ppf(0.99, 30))
    # a likely group gets a looser test, as a single loop does, but once, not once per loop
    assert group_threshold(np.full(10, 0.9), 3, 1.0, p) == pytest.approx(chi2.ppf(0.99, 30) + 2 * np.log(9))


@pytest.mark.parametrize("laps,side,every,seed,offset", [(2, 30, 4, 1, 0), (3, 30, 4, 0, 5)])
def test_consistent_false_group_rejected_with_the_margin_on_the_whole_sum(laps, side, every, seed, offset):
    data, truth, false, without = _grouped(laps, side, every, seed, offset)
    p = GraphParams().replace(robust={"group_margin_once": False})
    clean = robust_solve(without, p)
    res = robust_solve(data, p)
    assert not res.loop_inlier[false].any()
    assert res.loop_inlier[~false].all()
    assert ate(truth, res.poses) <= 1.01 * ate(truth, clean.poses) + 1e-3


def test_group_threshold_with_the_margin_once_grants_one_loop_its_tail():
    p = GraphParams()
    assert p.robust.group_margin_once
    m = p.robust.calibration_margin
    sigma0 = 0.2
    nan = np.full(10, np.nan)
    got = group_threshold(nan, 3, m * sigma0, p)
    assert got == pytest.approx(sigma0 * chi2.ppf(0.99, 30) + (m - 1) * sigma0 * chi2.ppf(0.99, 3))
    whole = group_threshold(nan, 3, m * sigma0, GraphParams().replace(robust={"group_margin_once": False}))
    assert got < whole
    # odometry that disagrees with the map at the solution holds the sum to its own variance, at most the whole sum
    assert got < group_threshold(nan, 3, m * sigma0, p, odometry_factor=2 * sigma0) < whole
    assert group_threshold(nan, 3, m * sigma0, p, odometry_factor=100 * sigma0) == pytest.approx(whole)
    # uncalibrated (scale 1): no margin to grant, the plain chi-square of n x dof
    assert group_threshold(nan, 3, 1.0, p) == pytest.approx(chi2.ppf(0.99, 30))
