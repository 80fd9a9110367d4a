"""One small real graph from ../shared/data (skipped where absent)."""
import numpy as np
import pytest

from graph import GraphParams, inject_false_loops, loop_scores, optimize, read_graph
from tests.graph.shared_graphs import se_sync_graph


@pytest.fixture(scope="module")
def csail(shared_data):
    return se_sync_graph(shared_data, "CSAIL")


def test_csail_least_squares_and_isam2(csail):
    # edges-only file (1045 poses, 1172 edges): odometry guess, then LM; iSAM2 must reach the same optimum. Its
    # near-singular information stops iSAM2's Cholesky on some machines (then it falls back to QR): whether that
    # happens depends on the BLAS build, so only the outcome is asserted
    lm = optimize(csail, GraphParams.preset("least_squares"), init="odometry")
    lago = optimize(csail, GraphParams.preset("least_squares"), init="lago")
    inc = optimize(csail, GraphParams.preset("least_squares"), solver="isam2")
    assert lm.final_cost == pytest.approx(20.2754, rel=1e-4)
    assert lago.final_cost == pytest.approx(lm.final_cost, rel=1e-6)
    assert inc.final_cost == pytest.approx(lm.final_cost, rel=1e-2)


def test_csail_half_false_loops(csail):
    clean = optimize(csail, GraphParams.preset("least_squares"))
    bad, injected = inject_false_loops(csail, 0.5, seed=1)
    res = optimize(bad, GraphParams())
    sc = loop_scores(res.loop_inlier, injected[bad.is_loop])
    assert sc.false_rejected == 1.0 and sc.recall == 1.0
    assert np.abs(res.poses[:, :2] - clean.poses[:, :2]).max() < 1e-3


def test_sphere2500_with_false_loops_keeps_every_true_loop():
    # sphere2500 (3D, in the gtsam wheel) with 10 % false loops. Which internal path reaches the answer (gated solve,
    # or its ungated fallback when the gate's start is bad) depends on floating-point details that differ between
    # machines and BLAS builds, so only the outcome is asserted: every true loop kept, every false one rejected, and
    # the map within 5 cm of the clean optimum
    from pathlib import Path

    import gtsam

    path = Path(gtsam.__file__).parent / "Data" / "sphere2500.txt"
    if not path.exists():
        pytest.skip(f"{path} not present")
    data = read_graph(path)
    bad, injected = inject_false_loops(data, 0.1, seed=1)
    res = optimize(bad, GraphParams())
    sc = loop_scores(res.loop_inlier, injected[bad.is_loop])
    assert sc.false_rejected == 1.0 and sc.recall == 1.0
    clean = optimize(data, GraphParams.preset("least_squares"))
    assert np.abs(res.poses[:, :3] - clean.poses[:, :3]).max() < 0.05   # m, on a sphere of radius 100 m
