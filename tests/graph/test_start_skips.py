"""The starts skipped where their outcome is known (graph.robust): the confident start when many confident clusters
misfit whole at its map (`confident_misfit_max_share`), the odometry start when the supported start rejected only
short-span loops (`odometry_start_short_skip`). Same loops and map as with every start run."""
import numpy as np
import pytest

from graph import GraphParams
from graph.robust import robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops

EVERY_START = {"confident_misfit_max_share": 1.0, "odometry_start_short_skip": False}


@pytest.mark.parametrize("seed", [1, 2])
def test_local_grouped_false_loops_same_decision_as_with_every_start(seed):
    truth = square_laps(3, 12)
    data, _ = noisy_graph(truth, np.random.default_rng(seed))
    bad, false = add_false_loops(data, "local-grouped", 0.5, seed)
    res = robust_solve(bad, GraphParams())
    every = robust_solve(bad, GraphParams().replace(robust=EVERY_START))
    assert res.loop_inlier[~false].all()
    assert not res.loop_inlier[false].any()
    assert np.array_equal(res.loop_inlier, every.loop_inlier)
    assert abs(ate(truth, res.poses) - ate(truth, every.poses)) <= 1e-5


def test_clean_graph_unchanged_by_the_skips():
    truth = square_laps(3, 12)
    data, _ = noisy_graph(truth, np.random.default_rng(3))
    res = robust_solve(data, GraphParams())
    every = robust_solve(data, GraphParams().replace(robust=EVERY_START))
    assert res.loop_inlier.all()
    assert np.array_equal(res.poses, every.poses)
