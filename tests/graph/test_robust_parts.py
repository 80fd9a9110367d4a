import numpy as np
import pytest

from graph import GraphParams, inject_false_loops, loop_scores
from graph.gnc import gm_weights, initial_mu, tls_weights
from graph.params import GncLoss, RobustParams
from graph.thresholds import fence_scale
from tests.graph.synth import noisy_graph, square_laps


def test_tls_weights_are_binary_outside_the_band_and_monotone():
    c2 = np.full(5, 10.0)
    r2 = np.array([0.0, 5.0, 10.0, 20.0, 1e6])
    w = tls_weights(r2, c2, mu=1.0)
    assert w[0] == 1.0 and w[-1] == 0.0
    assert np.all(np.diff(w) <= 0)
    w_big = tls_weights(r2, c2, mu=1e4)                    # mu -> inf: the truncated quadratic itself
    assert w_big.tolist() == [1.0, 1.0, pytest.approx(w_big[2]), 0.0, 0.0]
    assert np.all((0 <= gm_weights(r2, c2, 2.0)) & (gm_weights(r2, c2, 2.0) <= 1))


def test_initial_mu_rules():
    c2 = np.full(3, 10.0)
    assert initial_mu(GncLoss.TLS, np.array([1.0, 2.0, 3.0]), c2) < 0        # everything fits: nothing to do
    mu = initial_mu(GncLoss.TLS, np.array([1.0, 2.0, 1e4]), c2)
    assert 0 < mu < 1e-2
    assert initial_mu(GncLoss.GM, np.array([1.0, 40.0]), np.full(2, 10.0)) == pytest.approx(8.0)


def test_fence_scale_only_tightens():
    rng = np.random.default_rng(0)
    chi = rng.chisquare(3, 5000)
    assert fence_scale(chi, 3, factor=10.0) == 1.0                  # data that matches its stated noise
    s = fence_scale(chi * 1e-3, 3, factor=10.0)                     # information 1000x too loose
    assert 5e-3 < s < 2e-2
    assert fence_scale(chi[:5], 3, factor=10.0) == 1.0              # too few loops to tell


def test_injection_is_seeded_and_never_consecutive():
    data, _ = noisy_graph(square_laps(laps=2, side=5), np.random.default_rng(0))
    a, inj_a = inject_false_loops(data, 0.5, seed=7)
    b, inj_b = inject_false_loops(data, 0.5, seed=7)
    c, _ = inject_false_loops(data, 0.5, seed=8)
    assert a.equals(b) and not a.equals(c)
    assert inj_a.sum() == round(0.5 * data.num_loops) and inj_a[-1] and not inj_a[:data.num_edges].any()
    pa, pb = a.index_of(a.edge_from[inj_a]), a.index_of(a.edge_to[inj_a])
    assert np.all(np.abs(pa - pb) >= 2)
    assert np.isnan(a.probability[inj_a]).all()


def test_loop_scores():
    s = loop_scores(np.array([True, True, False, False, True]), np.array([False, True, True, False, False]))
    assert s.precision == pytest.approx(2 / 3) and s.recall == pytest.approx(2 / 3)
    assert s.false_rejected == pytest.approx(0.5) and (s.kept, s.rejected) == (3, 2)


def test_params_presets_and_validation():
    assert GraphParams.preset("default").robust.method.value == "consensus"
    default = GraphParams.preset("default")
    assert GraphParams.preset("fast").solver.lm_max_iterations < default.solver.lm_max_iterations
    assert GraphParams.preset("fast").incremental.batch_nodes > default.incremental.batch_nodes
    assert GraphParams.preset("robust_strict").robust.inlier_probability < default.robust.inlier_probability
    assert GraphParams.preset("least_squares").robust == RobustParams.preset("none")
    assert default.replace(robust="huber", solver="isam2").solver.method.value == "isam2"
    with pytest.raises(ValueError):
        GraphParams.preset("default").replace(robust="tukey")
    with pytest.raises(ValueError, match="gnc_mu_step"):
        GraphParams(robust={"gnc_mu_step": 1.0})
