"""Injected loops that state the truth (graph.labels): counted apart from the genuinely wrong ones."""
from __future__ import annotations

import numpy as np
import pytest

from graph.labels import coincidentally_true, count_false_loops, truth_residuals
from odometry.shared.poses import between
from tests.graph.synth import noisy_graph, square_laps


def _graph_with_injected():
    truth = square_laps(laps=2, side=5)            # 20 poses per lap: node k and k + 20 are the same place
    data, _ = noisy_graph(truth, np.random.default_rng(0))
    info = data.information[data.loop_edges()[0]]          # the generator's choice: the first loop's information
    right = between(truth[[3]], truth[[23]])[0] + [0.03, -0.02, 0.01]      # a draw landing on the revisit
    wrong = np.array([0.1, 0.2, 0.05])                                     # claims 6 and 30 are close: 4 m apart
    out = data.append_edges(data.node_ids[[3, 6]], data.node_ids[[23, 30]], np.array([right, wrong]),
                            np.array([info, info]), True)
    injected = np.zeros(out.num_loops, bool)
    injected[-2:] = True
    return out, truth, injected


def test_a_draw_on_a_real_revisit_is_coincidentally_true_and_a_wrong_one_is_not():
    data, truth, injected = _graph_with_injected()
    agree = coincidentally_true(data, truth)
    assert agree[~injected].all()                  # the graph's own loops agree with the truth
    assert agree[-2] and not agree[-1]
    r2 = truth_residuals(data, truth)
    assert r2[-1] > 1e3 * r2[-2]


def test_count_false_loops_applies_the_target_to_wrong_loops_only():
    data, truth, injected = _graph_with_injected()
    kept = np.ones(data.num_loops, bool)
    kept[-1] = False                               # the method kept the draw on the revisit, rejected the wrong one
    agree = coincidentally_true(data, truth)
    c = count_false_loops(injected, kept, agree)
    assert (c.injected, c.coincidental, c.coincidental_kept, c.wrong, c.wrong_kept) == (2, 1, 1, 1, 0)
    assert c.wrong_rejected == 1.0
    kept[-1] = True
    assert count_false_loops(injected, kept, agree).wrong_rejected == 0.0


def test_reference_of_the_wrong_size_is_an_error():
    data, truth, injected = _graph_with_injected()
    with pytest.raises(ValueError, match="reference has"):
        truth_residuals(data, truth[:-1])
    with pytest.raises(ValueError, match="one entry per loop"):
        count_false_loops(injected[:-1], injected, injected)
