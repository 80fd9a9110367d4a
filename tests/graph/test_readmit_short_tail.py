"""`robust.readmit_short_tail`: the re-admission of rejected loops that agree with a kept loop (graph.readmit) judges
short-span loops at the kept loops' own tail margin. On manhattan with Vertigo's local false loops, the loops it
re-admitted at the global margin were all false loops a few steps beside a true revisit (they agree with it and fit
once back); at the tail margin they stay out and every true loop is kept."""
import pytest

from graph import GraphParams
from graph.labels import coincidentally_true
from graph.robust import robust_solve
from tests.graph.synth import ate
from tests.graph.test_reach_tail import _local_false_loops


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_local_false_loops_rejected_and_true_short_loops_kept(seed):
    # three laps of a square, 40 true loops 3-15 steps apart, 4 false ones as far apart; the other short-span tests
    # off, so what keeps the false loops out is this setting
    bad, false, truth = _local_false_loops(seed)
    other = {"reach_tail": False, "own_cycle_test": False, "short_tail_screen": False}
    on = robust_solve(bad, GraphParams().replace(robust=other))
    off = robust_solve(bad, GraphParams().replace(robust={**other, "readmit_short_tail": False}))
    assert off.loop_inlier[false].any()
    assert not on.loop_inlier[false].any()
    assert on.loop_inlier[~false].all()
    assert ate(truth, on.poses) < ate(truth, off.poses)


def _local_50(manhattan, seed: int):
    from vslam.bench.graph_outliers import add_false_loops
    data, truth = manhattan
    bad, false = add_false_loops(data, "local", 0.5, seed)
    return bad, false & ~coincidentally_true(bad, truth), false


def test_manhattan_local_50_keeps_no_wrong_loop_and_every_true_one(manhattan):
    bad, wrong, false = _local_50(manhattan, 1)          # seed 1: a tuning draw of the bench
    res = robust_solve(bad, GraphParams())
    assert not res.loop_inlier[wrong].any()
    assert res.loop_inlier[~false].all()


def test_manhattan_local_50_without_the_setting_keeps_wrong_loops(manhattan):
    bad, wrong, false = _local_50(manhattan, 1)
    off = robust_solve(bad, GraphParams().replace(robust={"readmit_short_tail": False, "short_tail_screen": False}))
    assert off.loop_inlier[wrong].any()
    assert off.loop_inlier[~false].all()
