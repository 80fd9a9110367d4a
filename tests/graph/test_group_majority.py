"""The group test leaves out a cluster holding most of the kept loops (`group_skip_majority`): dropping it would
test the whole graph's residual against its variance factor, not one claim (graph.groups.drop_false_groups)."""
from pathlib import Path

import gtsam
import pytest

from graph import GraphParams
from graph.formats import read_graph
from graph.robust import robust_solve


@pytest.fixture(scope="module")
def sphere2500():
    path = Path(gtsam.__file__).parent / "Data" / "sphere2500.txt"
    if not path.exists():
        pytest.skip(f"{path} (gtsam's example data) not present")
    return read_graph(path)


def test_sphere2500_random_50_seed_3_keeps_its_one_big_cluster(sphere2500):
    # a reporting draw: every kept loop is one revisit cluster; with the variance factor from 5000 cycles (3 % lower
    # than from 20000) the objective was lower without it (odometry relaxed, the cluster charged its group
    # threshold) and it was dropped whole: 23.3 m, 33 % of the true loops kept
    from vslam.bench.graph_outliers import add_false_loops
    bad, false = add_false_loops(sphere2500, "random", 0.5, 3)
    p = GraphParams().replace(robust={"group_skip_majority": True, "calibration_propagate": 5000})
    res = robust_solve(bad, p)
    assert res.loop_inlier[~false].all()
    assert res.loop_inlier[false].mean() <= 0.01
