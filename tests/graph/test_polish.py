"""The final polish (graph.polish): the robust solve ends at the least-squares optimum of the loops it kept, not
where LM's cost tolerance stopped it."""
from __future__ import annotations

import gtsam
import numpy as np

from graph import GraphParams
from graph.batch import build, lm_params
from graph.factors import array_from_values, values_from_array
from graph.polish import polish
from graph.robust import robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps


def _graph():
    truth = square_laps(laps=4, side=10)
    data, _ = noisy_graph(truth, np.random.default_rng(3), sigma_xy=0.05, sigma_th=0.05)
    return data, truth


def _converged(data, start: np.ndarray) -> np.ndarray:
    """Plain LM to a relative tolerance of 1e-14: the least-squares optimum."""
    p = GraphParams.preset("least_squares")
    lp = lm_params(p, 1000)
    lp.setRelativeErrorTol(1e-14)
    lp.setAbsoluteErrorTol(0.0)
    graph = build(data, p).graph()
    return array_from_values(2, gtsam.LevenbergMarquardtOptimizer(graph, values_from_array(2, start), lp).optimize(),
                             data.num_nodes)


def test_robust_solve_reaches_the_optimum_whatever_lm_tolerance():
    # a loose LM tolerance stops the solve 1.3e-4 m (ATE) from the optimum of a 10 m map; the polish closes that
    data, truth = _graph()
    ref = _converged(data, truth)
    loose = GraphParams().replace(solver={"lm_relative_tol": 0.1, "init": "odometry"})
    res = robust_solve(data, loose)
    assert res.loop_inlier.all()
    assert ate(ref, res.poses) < 1e-5
    off = robust_solve(data, loose.replace(robust={"polish_max_steps": 0}))
    assert ate(ref, off.poses) > 10 * ate(ref, res.poses)      # the polish is what closed the gap
    np.testing.assert_array_equal(off.loop_inlier, res.loop_inlier)


def test_polish_at_the_optimum_stops_after_one_small_step():
    data, truth = _graph()
    ref = _converged(data, truth)
    graph = build(data, GraphParams.preset("least_squares")).graph()
    values, steps, why = polish(graph, values_from_array(2, ref), 2, GraphParams())
    assert steps == 1 and why.startswith("last step")
    assert np.abs(array_from_values(2, values, data.num_nodes)[:, :2] - ref[:, :2]).max() < 1e-6


def _far_start():
    # far from the optimum (headings off by up to 3 rad) undamped steps overshoot after a few good ones
    data, truth = _graph()
    graph = build(data, GraphParams.preset("least_squares")).graph()
    start = truth.copy()
    start[:, 2] += np.random.default_rng(0).uniform(-3.0, 3.0, len(start))
    return graph, values_from_array(2, start)


def test_polish_without_backtracking_refuses_a_step_that_raises_the_cost():
    # polish_backtracks 0: the polish stops at the first such step and keeps the last estimate that lowered the cost
    graph, v0 = _far_start()
    values, steps, why = polish(graph, v0, 2, GraphParams().replace(robust={"polish_backtracks": 0}))
    assert why == "a step raised the cost"
    assert graph.error(values) < graph.error(v0)
    lin = graph.linearize(values).optimize()
    assert graph.error(values.retract(lin)) > graph.error(values)      # the refused step


def test_backtracking_goes_on_where_the_full_step_overshoots():
    # halving the overshooting step lowers the cost further than stopping there; the cost never rises
    graph, v0 = _far_start()
    stopped, _, _ = polish(graph, v0, 2, GraphParams().replace(robust={"polish_backtracks": 0}))
    values, steps, _ = polish(graph, v0, 2, GraphParams())
    assert graph.error(values) < graph.error(stopped) < graph.error(v0)
