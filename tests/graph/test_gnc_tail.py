"""The consensus GNC (graph.tls.gnc_tls) once its weights are binary: a step whose labels still change is solved
to convergence (`consensus_binary_converge`), since from there on the surrogate is the TLS objective itself and a
few warm iterations per step only creep towards the next labels (city10000 at 50 % random-grouped false loops: a
tail of 40+ steps moving a few dozen labels each)."""
import numpy as np

import graph.robust as robust
import graph.tls as tls
from graph import GraphParams
from graph.batch import build, initial_guess
from graph.factors import graph_of, values_from_array
from graph.params import InitMethod
from tests.graph.synth import noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops


def _setup():
    data, _ = noisy_graph(square_laps(3, 20), np.random.default_rng(1), sigma_th=0.02)
    bad, false = add_false_loops(data, "random-grouped", 0.5, 1)
    built = build(bad, GraphParams().replace(robust="none"))
    v0 = values_from_array(2, initial_guess(bad, built, InitMethod.LAGO))    # the supported start: bent by the groups
    return built, v0, np.full(len(built.loops), 11.34), false


def _run(converge: bool):
    built, v0, c2, false = _setup()
    # one warm iteration per step: the creeping tail shows up on a graph this small
    params = GraphParams().replace(robust={"consensus_inner_iterations": 1, "consensus_binary_converge": converge})
    base = built.priors + built.odometry
    v, kept, outer, _ = tls.gnc_tls(base, built, v0, c2, np.arange(len(c2)), params)
    return kept, outer, tls.tls_objective(graph_of(base), built, v, c2), false


def test_binary_steps_whose_labels_change_are_solved_to_convergence():
    kept, outer, f, false = _run(True)
    kept0, outer0, f0, _ = _run(False)
    # same decision, no more outer steps, the objective no higher (to LM's tolerance)
    assert np.array_equal(kept, kept0)
    assert not kept[false].any()
    assert outer <= outer0
    assert f <= f0 * (1 + 1e-6)


def test_where_both_gnc_starts_agree_the_decision_is_the_one_without_the_kernel_start():
    # the groups pass the support test, so the odometry start runs too; both GNC starts keep the same loops, so
    # the DCS-kernel start adds nothing: the same loops and map as with it off, every true loop and no false one
    data, _ = noisy_graph(square_laps(3, 20), np.random.default_rng(1), sigma_th=0.01)
    bad, false = add_false_loops(data, "random-grouped", 0.3, 1)
    default = robust.robust_solve(bad, GraphParams())
    without = robust.robust_solve(bad, GraphParams().replace(robust={"kernel_start": False}))
    kept = np.asarray(default.loop_inlier, bool)
    assert np.array_equal(kept, np.asarray(without.loop_inlier, bool))
    np.testing.assert_allclose(default.poses, without.poses, atol=1e-9)
    assert not kept[false].any()
    assert kept[~false].all()
