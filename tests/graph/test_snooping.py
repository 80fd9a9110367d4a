"""`robust.data_snooping` (graph.snooping): on a graph whose kept loops follow the calibrated noise model, a loop
the heavy-tail margin lets in but the family-wise bound does not is dropped, and no true loop is; where the kept
loops are heavier-tailed than the model the test stands aside."""
import numpy as np
import pytest

from graph import GraphParams
from graph.robust import robust_solve
from graph.snooping import family_bound, heavy_tailed
from tests.graph.synth import ate, between, compose, noisy_graph, square_laps

ON = GraphParams().replace(robust={"data_snooping": True})


def _graph(seed: int, offset: float):
    """Four laps of a square, a loop at every revisit, stated noise 5x the actual (w10000 states its noise ~20x too
    loose in sigma), and one more loop at a true revisit whose measurement is `offset` metres off the truth along x
    (the last loop)."""
    truth = square_laps(4, 8)
    rng = np.random.default_rng(seed)
    data, _ = noisy_graph(truth, rng)
    n = data.num_nodes
    a = int(rng.integers(0, n // 4))
    b = a + 2 * 4 * 8          # two laps later (4 sides of 8 steps): the same place
    z = compose(between(truth[[b]], truth[[a]]), np.array([[offset, 0.0, 0.0]]))
    info = data.information[data.is_loop][0]
    bad = data.append_edges(data.node_ids[[b]], data.node_ids[[a]], z, info[None], True, np.full(1, np.nan))
    bad.information[:] /= 25.0
    return bad, truth


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_loop_beyond_the_family_bound_dropped_true_loops_kept(seed):
    # 0.2 m against a loop noise of 0.02 m: ~100 in calibrated chi-square units, inside the margin (10 x 11.3),
    # far outside the family-wise bound (~20 for a hundred loops)
    bad, truth = _graph(seed, 0.2)
    off = robust_solve(bad, GraphParams())
    on = robust_solve(bad, ON)
    assert off.loop_inlier[-1]                      # the margin lets it in
    assert not on.loop_inlier[-1]
    assert on.loop_inlier[:-1].all()
    assert ate(truth, on.poses) < ate(truth, off.poses)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_clean_graph_unchanged(seed):
    # seed 4: 2 of its 197 kept loops lie above the calibrated 0.99 quantile, more than the model's 1 %: the test
    # stands aside (the poses are the ones without it either way)
    bad, truth = _graph(seed, 0.0)
    off = robust_solve(bad, GraphParams())
    on = robust_solve(bad, ON)
    assert on.loop_inlier.all()
    assert ate(truth, on.poses) == pytest.approx(ate(truth, off.poses), abs=1e-6)


def test_heavy_tail_and_bound():
    # the bound grows with the number of tests; a tail heavier than the model is told apart
    assert family_bound(1, 3, 0.99) == pytest.approx(11.345, abs=1e-3)
    assert family_bound(54000, 3, 0.99) > 3 * family_bound(1, 3, 0.99)
    # residuals at a solution are the noise shrunk by each loop's redundancy (here 0.7): the model's tail or lighter
    rng = np.random.default_rng(0)
    at_solution = 0.7 * rng.chisquare(3, 5000)
    assert not heavy_tailed(at_solution, 3, 0.99)
    # one loop in ten with 3x the noise sigma: the tail of intel or garage
    assert heavy_tailed(at_solution * rng.choice([1.0, 9.0], 5000, p=[0.9, 0.1]), 3, 0.99)
