"""Loop labels against a reference trajectory: which injected ("false") loops happen to state the truth.

Vertigo's generator draws a false loop between two poses and claims they are close (translation ~ N(0, 0.3) per
axis, rotation ~ N(0, 10 deg)) with the information of the graph's loops. Where the trajectory really revisits
the place, the draw can land on the truth: on manhattan (M3500, a grid) poses 2580 and 2588 are 0 m and 0 deg
apart in ground truth, and a "false" group of ten loops claiming 0.26 m sits at r^2 = 3.0 against it under the
stated information, inside the chi-square 0.99 bound of 11.3 that a true loop is held to. Rejecting such a loop
is not what a robust method is for, and counting it as a false loop kept charges the method for agreeing with the
truth. So the benchmark tells three kinds of loops apart: the graph's own loops; injected loops that agree with
the reference ("coincidentally true": their measurement against the reference relative pose, as a squared
Mahalanobis distance under the loop's stated information, within the chi-square quantile `probability` of its
degrees of freedom: the test a true loop of the graph passes); and the rest, the genuinely wrong loops, to which
the false-rejection target applies.

The reference is the ground truth where the graph has it; for graphs without (intel, CSAIL, garage, w10000) the
clean optimum is the best stand-in, and the label then says "agrees with the map the true loops make".
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from graph.batch import build
from graph.factors import values_from_array
from graph.model import TANGENT_DIM, PoseGraphData
from graph.params import GraphParams


def truth_residuals(data: PoseGraphData, reference: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis error of every loop's measurement against the relative pose of its two nodes in
    `reference` ((N, 3) planar or (N, 7) 3D poses in node order), under the loop's stated information."""
    reference = np.asarray(reference, float)
    if len(reference) != data.num_nodes:
        raise ValueError(f"reference has {len(reference)} poses for a graph of {data.num_nodes} nodes")
    built = build(data, GraphParams.preset("least_squares"))
    return built.r2(values_from_array(data.dim, reference))


def coincidentally_true(data: PoseGraphData, reference: np.ndarray, probability: float = 0.99) -> np.ndarray:
    """Per loop (loop order): its measurement agrees with `reference` within the chi-square `probability` quantile
    of its stated information (see the module doc). Meant for the injected loops; the graph's own loops pass it
    too (on manhattan their r^2 against ground truth is at most 0.52)."""
    return truth_residuals(data, reference) <= float(chi2.ppf(probability, TANGENT_DIM[data.dim]))


@dataclass
class FalseLoopCount:
    """What a robust method did with the injected loops, split by whether they agree with the reference."""

    injected: int                 # injected loops
    coincidental: int             # of which agree with the reference (coincidentally true)
    coincidental_kept: int        # ... and were kept
    wrong: int                    # injected loops that do not agree with the reference
    wrong_kept: int               # ... and were kept

    @property
    def wrong_rejected(self) -> float:
        """Share of the genuinely wrong injected loops rejected (1 when there are none): the 99 % target."""
        return 1.0 - self.wrong_kept / self.wrong if self.wrong else 1.0


def count_false_loops(injected: np.ndarray, kept: np.ndarray, agree: np.ndarray) -> FalseLoopCount:
    """Split the injected loops (`injected`: mask per loop, loop order) into coincidentally true ones (`agree`,
    from `coincidentally_true` on the contaminated graph: computed once per draw, shared by every method) and wrong
    ones, and count how many of each `kept` (mask per loop) holds."""
    injected, kept, agree = (np.asarray(x, bool) for x in (injected, kept, agree))
    if not injected.shape == kept.shape == agree.shape:
        raise ValueError(f"masks must have one entry per loop; got {injected.shape}, {kept.shape}, {agree.shape}")
    agree = agree & injected
    wrong = injected & ~agree
    return FalseLoopCount(int(injected.sum()), int(agree.sum()), int((agree & kept).sum()), int(wrong.sum()),
                          int((wrong & kept).sum()))
