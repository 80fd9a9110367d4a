"""`robust.consensus_isam2_steps`: the warm GNC steps of the consensus solve taken by iSAM2 updates (only the
re-weighted loops removed and re-added) reach the same loop labels as the LM steps."""
import numpy as np

from graph import GraphParams, optimize
from tests.graph.test_consensus_trial import lone_loop_graph


def _both(data):
    off = optimize(data, GraphParams().replace(robust={"consensus_isam2_steps": False}))
    on = optimize(data, GraphParams().replace(robust={"consensus_isam2_steps": True}))
    return off, on


def test_isam2_steps_keep_the_labels_of_lm_steps_among_many_false_loops():
    _, dd, false, _ = lone_loop_graph(bias=0.001)
    off, on = _both(dd)
    assert np.array_equal(on.loop_inlier, off.loop_inlier)
    assert on.loop_inlier[~false].all() and not on.loop_inlier[false].any()
    assert np.max(np.abs(on.poses - off.poses)) < 1e-3


def test_isam2_steps_with_every_step_re_weighting_more_than_the_cap_fall_back_to_lm():
    # a cap of 0 loops: every step that changes a weight is an LM step, the same solve as with the setting off
    _, dd, _, _ = lone_loop_graph(bias=0.001)
    off = optimize(dd, GraphParams().replace(robust={"consensus_isam2_steps": False}))
    capped = optimize(dd, GraphParams().replace(robust={"consensus_isam2_steps": True,
                                                        "consensus_isam2_max_changed": 0}))
    assert np.array_equal(capped.loop_inlier, off.loop_inlier)
    assert np.allclose(capped.poses, off.poses, atol=1e-9)
