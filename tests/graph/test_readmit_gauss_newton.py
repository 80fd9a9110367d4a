"""The re-admission's GNC (graph.readmit, `readmit_isam2_steps`): its iSAM2 steps by Gauss-Newton
(`readmit_isam2_gauss_newton`) and without the final warm solve its caller repeats (`gnc_tls(final_solve=False)`)
reach the labels of dogleg steps and of LM steps: the kept loops are known inliers and only a few candidates are
re-weighted against a fixed map."""
import numpy as np
import pytest

import graph.tls as tls
from graph import GraphParams, optimize
from graph.batch import build, initial_guess, solve_lm
from graph.factors import graph_of, values_from_array
from graph.params import InitMethod
from tests.graph.synth import noisy_graph, square_laps
from tests.graph.test_consensus_trial import lone_loop_graph
from vslam.bench.graph_outliers import add_false_loops


def _readmission_problem():
    """Known inliers: the true loops but six; candidates: those six and the false loops (as the re-admission's GNC
    sees them, from the map solved without the candidates)."""
    data, _ = noisy_graph(square_laps(3, 20), np.random.default_rng(2), sigma_th=0.01)
    bad, false = add_false_loops(data, "random", 0.3, 5)
    built = build(bad, GraphParams().replace(robust="none"))
    c2 = np.full(len(built.loops), 11.34)
    true = ~false
    out = np.flatnonzero(true)[[2, 9, 15, 21, 28, 33]]
    inlier = true.copy()
    inlier[out] = False
    guess = values_from_array(2, initial_guess(bad, built.subset(inlier), InitMethod.LAGO))
    v0, _ = solve_lm(built.graph(inlier), guess, GraphParams())
    known = built.priors + built.odometry + [f for f, k in zip(built.loops, inlier.tolist()) if k]
    cand = ~inlier
    return built, known, v0, c2, cand, true


@pytest.mark.parametrize("final_solve", [True, False])
@pytest.mark.parametrize("gauss_newton", [True, False])
def test_readmission_gnc_by_gauss_newton_isam2_steps_keeps_the_labels_of_lm_steps(gauss_newton, final_solve):
    built, known, v0, c2, cand, true = _readmission_problem()
    sub = built.subset(cand)
    label = np.arange(int(cand.sum()))
    v_lm, kept_lm, _, _ = tls.gnc_tls(known, sub, v0, c2[cand], label, GraphParams())
    v, kept, _, _ = tls.gnc_tls(known, sub, v0, c2[cand], label, GraphParams(), gauss_newton, final_solve=final_solve,
                                isam2_steps=True)
    assert np.array_equal(kept, kept_lm)
    assert kept.any() and np.array_equal(kept, true[cand])     # the six true loops back, every false loop out
    # the caller's re-solve of those labels ends at the same TLS objective from either map (LM's tolerance)
    trial = ~cand
    trial[np.flatnonzero(cand)[kept]] = True
    base = graph_of(built.priors + built.odometry)
    f = [tls.tls_objective(base, built, solve_lm(built.graph(trial), x, GraphParams())[0], c2) for x in (v, v_lm)]
    assert f[0] == pytest.approx(f[1], rel=1e-5)

def test_robust_solve_labels_with_and_without_gauss_newton_readmission_steps():
    _, dd, false, _ = lone_loop_graph(bias=0.001)
    gn = optimize(dd, GraphParams())
    dogleg = optimize(dd, GraphParams().replace(robust={"readmit_isam2_gauss_newton": False}))
    assert np.array_equal(gn.loop_inlier, dogleg.loop_inlier)
    assert gn.loop_inlier[~false].all() and not gn.loop_inlier[false].any()
    assert np.max(np.abs(gn.poses - dogleg.poses)) < 1e-3
