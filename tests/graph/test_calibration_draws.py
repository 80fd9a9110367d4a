"""The split calibration (graph.calibration) on parking-garage under injected random false loops: the variance
factors do not move with the draw beyond the sampling error of a median over `calibration_propagate` cycles, and
the true loops at the edge of their thresholds stay kept."""
import numpy as np
import pytest
from scipy.stats import chi2

from graph import GraphParams
from graph.calibration import split_factors
from graph.robust import robust_solve
from graph.support import cycle_support
from tests.graph.shared_graphs import se_sync_graph


@pytest.fixture(scope="module")
def garage(shared_data):
    return se_sync_graph(shared_data, "parking-garage")


def _factors(data):
    p = GraphParams().robust
    cycles = cycle_support(data, p.support_window, float(chi2.ppf(p.support_probability, 6)),
                           decompose=p.calibration_propagate)
    return split_factors(cycles)


def test_translation_factor_steady_over_random_draws(garage):
    from vslam.bench.graph_outliers import add_false_loops
    clean = _factors(garage).translation
    # 5000 cycles: 7.24e-5 (seed 3) to 7.95e-5 (seed 1) at 30 %, 7.70e-5 clean
    for seed in (1, 2, 3):
        bad, _ = add_false_loops(garage, "random", 0.3, seed)
        assert _factors(bad).translation == pytest.approx(clean, rel=0.03)


def test_garage_random_30_seed_3_keeps_every_true_loop(garage):
    # a reporting draw: three heavy-tailed true loops (526 -> 646, 644 -> 711, 771 -> 1016) were dropped when the
    # draw moved the translation factor to 7.24e-5
    from vslam.bench.graph_outliers import add_false_loops
    bad, false = add_false_loops(garage, "random", 0.3, 3)
    res = robust_solve(bad, GraphParams())
    assert res.loop_inlier[~false].all()
    assert not res.loop_inlier[false].any()
    assert np.isfinite(res.poses).all()
