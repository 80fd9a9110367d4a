"""graph.readmit: loops the joint trial of the unsupported loops pushed out get one joint re-solve.

Before: on intel with 10 % random false loops (seed 2) the trial's GNC, started with a false loop pulling through
its convex surrogate, dropped 2 of the 785 true loops the consensus had kept (r^2 3.7 and 4.1 against 1.55 at its
result, 0.6 at the clean optimum); nothing tried them again and the map ended 4.9 mm from the clean optimum."""
import gtsam
import numpy as np
import pytest

import graph.robust as robust
from graph import GraphParams, read_graph
from graph.batch import build, initial_guess, lm_params
from graph.factors import graph_of, values_from_array
from graph.params import InitMethod
from graph.readmit import readmit_dropped
from tests.graph.synth import noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops


def _setup(false_fraction: float):
    data, _ = noisy_graph(square_laps(3, 20), np.random.default_rng(2), sigma_th=0.01)
    bad, false = add_false_loops(data, "random", false_fraction, 5)
    params = GraphParams()
    built = build(bad, params.replace(robust="none"))
    c2 = np.full(len(built.loops), 11.34)
    base = graph_of(built.priors + built.odometry)

    def objective(v):
        return robust.tls_objective(base, built, v, c2)

    def solve(g, v, n):
        opt = gtsam.LevenbergMarquardtOptimizer(g, v, lm_params(params, n))
        return opt.optimize(), int(opt.iterations())
    return bad, built, false, c2, objective, solve, params


def test_dropped_true_loops_come_back_and_a_misfitting_one_stays_out():
    bad, built, false, c2, objective, solve, params = _setup(0.1)
    assert false.any()
    true = ~false
    # the map solved with the true loops, then two of them pushed out as a trial might
    guess = values_from_array(2, initial_guess(bad, built.subset(true), InitMethod.LAGO))
    v_all, _ = solve(built.graph(true), guess, 100)
    lost = np.flatnonzero(true)[[3, 17]]
    inlier = true.copy()
    inlier[lost] = False
    v, _ = solve(built.graph(inlier), v_all, 100)
    notes: list[str] = []
    v2, kept, _ = readmit_dropped(built, v, inlier, true, c2, objective, solve, params, notes)
    assert kept[lost].all() and np.array_equal(kept, true)
    assert objective(v2) <= objective(v)
    # a false loop that had been kept "before" does not fit once back: the whole joint re-admission is refused
    before = true.copy()
    before[np.flatnonzero(false)[0]] = True
    notes = []
    v3, kept3, _ = readmit_dropped(built, v_all, true, before, c2, objective, solve, params, notes)
    assert np.array_equal(kept3, true)
    assert "stay out" in notes[-1]


def test_intel_random_false_loops_keep_every_true_loop(shared_data):
    p = shared_data / "posegraphs" / "se-sync" / "intel.g2o"
    if not p.exists():
        pytest.skip(f"{p} not present")
    bad, false = add_false_loops(read_graph(p), "random", 0.1, 2)
    res = robust.robust_solve(bad, GraphParams())
    kept = np.asarray(res.loop_inlier, bool)
    assert kept[~false].all()                  # before: 2 of 785 true loops dropped by the trial
    assert not kept[false].any()
