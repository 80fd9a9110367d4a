"""Many groups of consistent false loops spread over a map (Vertigo's random-grouped policy on manhattan / M3500):
GNC's convex surrogate is bent by them from both consensus starts, and the third start (graph.kernel_start: a DCS
solve from the odometry chain, then TLS descent) is what finds the clean solution."""
import numpy as np

from graph import GraphParams
from graph.factors import graph_of, squared_residuals, values_from_array
from graph.kernel_start import dcs_solve, tls_descent
from graph.robust import robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops


def test_tls_descent_from_a_kernel_solve_drops_a_false_group():
    from graph.batch import build, initial_guess
    from graph.params import InitMethod
    # little heading drift and a kernel as wide as the true loops' residuals at the odometry chain (r^2 ~ 5e2-1e4
    # here; the false group's ~ 1e7): DCS from the odometry works only where the drift is small against the kernel
    # (under large drift the other consensus starts win the objective)
    truth = square_laps(2, 30)
    data, _ = noisy_graph(truth, np.random.default_rng(1), sigma_th=0.001, loop_every=4)
    info = data.information[data.is_loop][0]
    k = np.arange(10)
    bad = data.append_edges(data.node_ids[62 + k], data.node_ids[2 + k], np.zeros((10, 3)),
                            np.broadcast_to(info, (10, 3, 3)), True, np.full(10, np.nan))
    built = build(bad, GraphParams.preset("least_squares"))
    base = built.priors + built.odometry
    odo = values_from_array(2, initial_guess(bad, built, InitMethod.ODOMETRY))
    v = dcs_solve(base, built.loops, odo, 1e3, GraphParams())
    c2 = np.full(len(built.loops), 11.34 * 10)
    v, kept, solves = tls_descent(base, built, v, c2, GraphParams(), 10)
    assert not kept[-10:].any() and kept[:-10].all()
    assert 1 <= solves <= 10
    # the descent never ends above its start in the TLS objective
    assert float(graph_of(base).error(v)) + 0.5 * np.minimum(squared_residuals(built.loops, v), c2).sum() <= \
        float(graph_of(base).error(odo)) + 0.5 * np.minimum(squared_residuals(built.loops, odo), c2).sum()


def test_manhattan_random_grouped_tuning_draw(manhattan):
    # tuning draw (seed 3; seed 2 is the benchmark's reporting draw): 63 groups of 10 false loops. Before the
    # kernel start: 31.3 m ATE, 120 true loops dropped, 19 false kept (clean ATE 0.794 m)
    data, truth = manhattan
    bad, false = add_false_loops(data, "random-grouped", 0.3, 3)
    res = robust_solve(bad, GraphParams())
    clean = robust_solve(data, GraphParams())
    assert not res.loop_inlier[false].any()
    assert res.loop_inlier[~false].all()
    assert ate(truth, res.poses) <= 1.05 * ate(truth, clean.poses) + 0.01
