"""graph.local_solve: a solve over a neighbourhood of the map with every other pose held."""
import numpy as np
import pytest

from graph import GraphParams
from graph.batch import build, solve_lm
from graph.factors import array_from_values, values_from_array
from graph.local_solve import local_solve, neighbourhood
from tests.graph.synth import noisy_graph, square_laps


def test_neighbourhood_marks_each_stretch_and_its_window():
    m = neighbourhood(30, np.array([10, 25]), np.array([5, 27]), 2)
    assert np.flatnonzero(m).tolist() == list(range(3, 13)) + list(range(23, 30))


def _graph(seed: int = 1):
    truth = square_laps(3, 8)
    data, _ = noisy_graph(truth, np.random.default_rng(seed))
    built = build(data, GraphParams.preset("least_squares"))
    # a start away from the optimum: the odometry chain
    return data, built, values_from_array(2, data.poses)


def test_every_node_free_is_the_whole_solve():
    data, built, v0 = _graph()
    keep = np.ones(len(built.loops), bool)
    full, _ = solve_lm(built.graph(keep), v0, GraphParams())
    loc, _ = local_solve(built, keep, v0, np.ones(data.num_nodes, bool), 2, GraphParams())
    assert array_from_values(2, loc, data.num_nodes) == pytest.approx(array_from_values(2, full, data.num_nodes),
                                                                      abs=1e-6)


def test_held_nodes_stay_and_the_error_falls():
    data, built, v0 = _graph()
    keep = np.ones(len(built.loops), bool)
    full, _ = solve_lm(built.graph(keep), v0, GraphParams())
    # from the optimum, disturb a stretch, then solve only around it
    p = array_from_values(2, full, data.num_nodes)
    p[40:50, :2] += 0.3
    start = values_from_array(2, p)
    free = neighbourhood(data.num_nodes, np.array([40]), np.array([49]), 3)
    out, _ = local_solve(built, keep, start, free, 2, GraphParams())
    q = array_from_values(2, out, data.num_nodes)
    assert q[~free] == pytest.approx(p[~free], abs=1e-12)
    g = built.graph(keep)
    assert g.error(out) < 0.1 * g.error(start)
