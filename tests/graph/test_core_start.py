"""The start from the largest confident clusters grown by size (graph.core_start): on a graph with groups of
consistent false loops (Vertigo's random-grouped policy) its map fits the true loops and not the false groups, and
the whole solve that reaches it (every solve counted as one that fills in: `solver.direct_max_cost` 0) keeps every
true loop and rejects every false one."""
import numpy as np
import pytest

from graph import GraphParams
from graph.core_start import core_start, grow_core, split_share
from graph.robust import _prepare, robust_solve
from tests.graph.synth import ate, noisy_graph, square_laps
from vslam.bench.graph_outliers import add_false_loops


def _grouped(laps: int, side: int, seed: int):
    truth = square_laps(laps, side)
    data, _ = noisy_graph(truth, np.random.default_rng(seed))
    bad, false = add_false_loops(data, "random-grouped", 0.5, seed)
    return bad, false, truth


@pytest.mark.parametrize("laps,side,seed", [(4, 12, 1), (3, 20, 3)])
def test_core_map_fits_the_true_loops_and_not_the_false_groups(laps, side, seed):
    bad, false, _ = _grouped(laps, side, seed)
    cs, c2 = _prepare(bad, GraphParams())
    f, values, kept = core_start(cs, c2)
    fit = cs.built.r2(values) <= c2
    assert fit[~false].all()
    assert not fit[false].any()
    assert not kept[false].any() and kept.any()
    assert f == pytest.approx(cs.objective(values, c2))


def test_no_core_when_even_the_largest_clusters_fill_in():
    bad, _, _ = _grouped(4, 12, 1)
    cs, c2 = _prepare(bad, GraphParams().replace(robust={"core_max_cost": 0.0}))
    assert core_start(cs, c2) is None


@pytest.mark.parametrize("laps,side,seed", [(4, 12, 1), (3, 20, 3)])
def test_core_map_splits_no_cluster_and_the_odometry_map_does(laps, side, seed):
    bad, _, _ = _grouped(laps, side, seed)
    cs, c2 = _prepare(bad, GraphParams())
    core = grow_core(cs, c2)
    assert split_share(cs, c2, core) == 0.0
    # a cluster outside the core with one loop fitting and the rest not counts as split
    label = np.where(cs.cand & ~core[2], cs.confident[0], -1)
    ids, counts = np.unique(label[label >= 0], return_counts=True)
    loops = np.flatnonzero(label == ids[counts >= 2][0])
    strained = c2.copy()
    strained[loops] = 0.0
    strained[loops[0]] = np.inf
    out = len(np.unique(label[label >= 0]))
    assert split_share(cs, strained, core) == pytest.approx(1.0 / out)


@pytest.mark.parametrize("laps,side,seed", [(4, 12, 1), (3, 20, 3)])
@pytest.mark.parametrize("core,alone", [(True, True), (True, False), (False, False)])
def test_labels_right_when_the_cluster_path_is_taken(laps, side, seed, core, alone):
    bad, false, truth = _grouped(laps, side, seed)
    keep = np.ones(bad.num_edges, bool)
    keep[bad.loop_edges()[false]] = False
    clean = robust_solve(bad.with_edges(keep), GraphParams())
    res = robust_solve(bad, GraphParams().replace(solver={"direct_max_cost": 0.0}, robust={"core_start": core,
                                                                                          "core_alone": alone}))
    assert res.loop_inlier[~false].all()
    assert not res.loop_inlier[false].any()
    assert ate(truth, res.poses) <= 1.01 * ate(truth, clean.poses) + 1e-3
