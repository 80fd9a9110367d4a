"""The confident-loops start (graph.confident): loops agreeing pairwise under the calibrated threshold, in runs."""
import numpy as np
from scipy.stats import chi2

from graph import GraphParams
from graph.confident import confident_loops
from graph.robust import robust_solve
from graph.support import cycle_support
from tests.graph.synth import ate, noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops


def _graph_with_false_loops(seed: int = 1):
    truth = square_laps(3, 12)
    data, _ = noisy_graph(truth, np.random.default_rng(seed))
    bad, false = add_false_loops(data, "random", 0.5, seed)
    return bad, false, truth


def test_true_revisits_are_confident_and_random_false_loops_are_not():
    bad, false, _ = _graph_with_false_loops()
    p = GraphParams()
    cycles = cycle_support(bad, p.robust.support_window, float(chi2.ppf(p.robust.support_probability, 3)))
    # the noise is stated as drawn: variance factor ~1
    mask = confident_loops(cycles, bad.num_loops, 3, 1.0, p) >= 0
    assert mask[~false].mean() >= 0.9
    assert not mask[false].any()


def test_a_lone_agreeing_pair_is_not_confident():
    bad, false, _ = _graph_with_false_loops()
    p = GraphParams()
    cycles = cycle_support(bad, p.robust.support_window, float(chi2.ppf(p.robust.support_probability, 3)))
    loose = confident_loops(cycles, bad.num_loops, 3, 1e12, p.replace(robust={"confident_min_cluster": 2})) >= 0
    strict = confident_loops(cycles, bad.num_loops, 3, 1e12, p.replace(robust={"confident_min_cluster": 10 ** 6})) >= 0
    assert loose.sum() >= strict.sum() and not strict.any()


def test_confident_start_keeps_the_solution_on_random_false_loops():
    bad, false, truth = _graph_with_false_loops(2)
    keep = np.ones(bad.num_edges, bool)
    keep[bad.loop_edges()[false]] = False
    clean = robust_solve(bad.with_edges(keep), GraphParams())
    for on in (True, False):
        res = robust_solve(bad, GraphParams().replace(robust={"confident_start": on}))
        assert res.loop_inlier[~false].all()
        assert not res.loop_inlier[false].any()
        assert ate(truth, res.poses) <= 1.05 * ate(truth, clean.poses) + 0.01
