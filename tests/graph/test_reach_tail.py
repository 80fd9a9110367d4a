"""`robust.reach_tail`: false loops between nodes a few steps apart (Vertigo's local policy) differ from the odometry
between them by little in absolute terms and fit the global calibrated margin; judged at the margin the kept loops'
own residual tail asks for (short spans only), they are rejected and every true loop stays."""
import numpy as np
import pytest

from graph import GraphParams
from graph.labels import coincidentally_true
from graph.robust import robust_solve
from graph.thresholds import short_span, tail_margin
from tests.graph.synth import ate, between, compose, noisy_graph, square_laps


def _local_false_loops(seed: int):
    """Three laps of a square, a loop at every revisit, 40 true loops 3-15 steps apart, 4 false ones as far apart
    (0.25 m, 6 degrees off the truth); stated noise 5x the actual (public graphs state theirs too loose)."""
    truth = square_laps(3, 12)
    rng = np.random.default_rng(seed)
    data, _ = noisy_graph(truth, rng)
    n = data.num_nodes
    info = data.information[data.is_loop][0]

    def local(k: int, noise) -> tuple:
        i = rng.integers(0, n - 20, k)
        j = i + rng.integers(3, 16, k)
        return j, i, compose(between(truth[j], truth[i]), noise(k))

    jt, it, zt = local(40, lambda k: rng.normal(0.0, [0.02, 0.02, 0.01], (k, 3)))
    jf, i_f, zf = local(4, lambda k: np.column_stack([0.25 * np.cos(a := rng.uniform(0, 2 * np.pi, k)),
                                                      0.25 * np.sin(a), np.radians(6.0) * rng.choice([-1, 1], k)]))
    bad = data.append_edges(data.node_ids[np.r_[jt, jf]], data.node_ids[np.r_[it, i_f]], np.vstack([zt, zf]),
                            np.broadcast_to(info, (44, 3, 3)), True, np.full(44, np.nan))
    bad.information[:] /= 25.0
    false = np.r_[np.zeros(bad.num_loops - 4, bool), np.ones(4, bool)]
    return bad, false, truth


@pytest.mark.parametrize("seed", [0, 1])
def test_reach_tail_rejects_local_false_loops_and_keeps_true_ones(seed):
    bad, false, truth = _local_false_loops(seed)
    # the other short-span tests off (readmit_short_tail rejects these too: tests/graph/test_readmit_short_tail.py)
    other = {"own_cycle_test": False, "readmit_short_tail": False, "short_tail_screen": False}
    off = robust_solve(bad, GraphParams().replace(robust={"reach_tail": False, **other}))
    on = robust_solve(bad, GraphParams().replace(robust={"reach_tail": True, **other}))
    assert off.loop_inlier[false].any()          # the global margin lets them in
    assert not on.loop_inlier[false].any()
    assert on.loop_inlier[~false].all()
    assert ate(truth, on.poses) < ate(truth, off.poses)


def test_tail_margin_bounds_and_short_span():
    p = GraphParams()
    rng = np.random.default_rng(0)
    r2 = rng.chisquare(3, 500)
    # residuals as the stated model predicts (or heavier): the factor x their quantile reaches the global margin
    assert tail_margin(2.0 * r2, 1.0, 3, p) == pytest.approx(p.robust.calibration_margin)
    assert tail_margin(0.01 * r2, 1.0, 3, p) == pytest.approx(1.0)              # never below the quantile itself
    m = tail_margin(0.5 * r2, 1.0, 3, p)
    assert 1.0 < m < p.robust.calibration_margin
    # a short-span loop is accepted within fence_factor x the kept loops' fence_quantile of r^2
    assert m * 11.345 == pytest.approx(p.robust.fence_factor * np.quantile(0.5 * r2, p.robust.fence_quantile), rel=1e-3)
    assert tail_margin(r2[:3], 1.0, 3, p) == p.robust.calibration_margin         # too few kept loops: global
    assert short_span(np.array([1, 20, 21]), 10).tolist() == [True, True, False]


def test_manhattan_local_50_with_reach_tail(manhattan):
    # seed 3 (a reporting draw of the bench; seed 1 tuned): without the setting 2 wrong loops are kept (0.8055 m;
    # 4 and 0.8133 m before readmit_short_tail)
    from vslam.bench.graph_outliers import add_false_loops
    data, truth = manhattan
    bad, false = add_false_loops(data, "local", 0.5, 3)
    res = robust_solve(bad, GraphParams().replace(robust={"reach_tail": True}))
    wrong = false & ~coincidentally_true(bad, truth)
    assert not res.loop_inlier[wrong].any()
    assert res.loop_inlier[~false].all()


def test_manhattan_random_grouped_with_reach_tail(manhattan):
    # tests/graph/test_kernel_start.py's draw with the setting on: a tightened decision must not trade the start
    # that finds the clean map for a bent one (an earlier version without the first decision as a start: 24 m)
    from vslam.bench.graph_outliers import add_false_loops
    data, truth = manhattan
    bad, false = add_false_loops(data, "random-grouped", 0.3, 3)
    res = robust_solve(bad, GraphParams().replace(robust={"reach_tail": True}))
    assert not res.loop_inlier[false].any()
    assert res.loop_inlier[~false].all()
    assert ate(truth, res.poses) <= 1.05 * 0.7942 + 0.01
