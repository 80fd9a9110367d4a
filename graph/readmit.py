"""Re-admission of loops the joint trial of the unsupported loops dropped (step 4 of graph.robust).

The unsupported loops are judged by a GNC over them and every loop kept so far, started from the solution, so
the map can move to a lone true loop. That GNC starts from its convex surrogate, where a false loop among the
tried ones still pulls on the map; it may push out a loop the consensus and the group test had kept, and once
the false loop is truncated the GNC ends in a minimum without it (intel, 10 % random, seed 2: loops 667 and 669
of 785 true, kept by the consensus, r^2 0.6 against a threshold of 1.55 at the clean optimum, 3.7 and 4.1 at the
trial's result; the map 4.9 mm ATE from the clean optimum). The trial was there to judge the unsupported loops,
not to revisit the decided ones, so each loop it dropped gets one joint re-solve: all of them back, LM from the
trial's solution, kept when every one of them fits its own threshold there and the TLS objective is not higher.
Nothing new enters the candidate set (only loops that had passed the consensus and the group test), so a false
loop is re-admitted only if it had already been kept before the trial.
"""
from __future__ import annotations

from typing import Callable

import gtsam
import numpy as np

from graph.params import GraphParams


def readmit_dropped(built, values: gtsam.Values, inlier: np.ndarray, before: np.ndarray, c2: np.ndarray,
                    objective: Callable[[gtsam.Values], float], solve: Callable, params: GraphParams,
                    notes: list[str]) -> tuple[gtsam.Values, np.ndarray, int]:
    """(values, inlier, LM iterations) after one joint re-solve with the loops kept `before` the trial and not in
    `inlier` now; `solve(graph, values, iterations)` -> (values, iterations) is the LM of the caller, `objective`
    its TLS objective over every loop."""
    lost = before & ~inlier
    if not lost.any():
        return values, inlier, 0
    trial = inlier | lost
    v, it = solve(built.graph(trial), values, params.solver.lm_max_iterations)
    fits = bool(np.all(built.r2(v)[lost] <= c2[lost]))
    if fits and objective(v) <= objective(values):
        notes.append(f"re-admitted {int(lost.sum())} loops the joint trial had dropped (they fit once back)")
        return v, trial, it
    notes.append(f"{int(lost.sum())} loops dropped by the joint trial stay out (misfit or higher objective)")
    return values, inlier, it
