"""The own-cycle test of short-span loops: a kept loop between nodes a few steps apart is dropped when the cycle it
closes with the odometry between its ends is worse than the agreeing cycles of the kept loops show.

A false loop between nodes a few steps apart (Vertigo's local policy) differs from the odometry between them by
centimetres: at the solution the short odometry bends towards it, and the global threshold (chi-square x
`calibration_margin`, which must cover the heavy residual tails of real graphs and the strain a lone loop closing a
long drift keeps) lets some of them in (sphere2500 local 50 %: 5-6 kept, ATE 0.23-0.25 m against 0.203 m). Over a
span of at most `support_window` steps the loop closes a cycle with the odometry alone, the same kind of short
cycle the cycle test (graph.support) closes with two loops (at most `support_window` odometry steps at each end). No drift and no
map enters it, so the agreeing cycles of the kept loops are its reference: a short-span loop whose own cycle error
exceeds their `own_cycle_quantile` (0.999) is rejected. The reference is read from the graph, not fixed: it is
2.0 x chi-square(0.99) on sphere2500 (its cycles follow chi-square on the calibrated model), 5.5 x on manhattan
and 10.5 x on intel (heavy tails; intel's worst true short-span loop sits at 8.5 x); it is never tighter than the
chi-square quantile of the inlier test and never looser than the loop's own threshold. The test is on the model
the loops are judged on (calibrated: graph.calibration), with the cycles' covariances propagated through the
cycle in 3D where the calibration propagated them (summed, the lever arms of 10-20 odometry steps put sphere2500's
reference at 8 x chi-square and left the worst false loops in).
"""
from __future__ import annotations

import numpy as np

from graph.calibration import VarianceFactors, scale_information
from graph.model import PoseGraphData
from graph.support import CycleSupport, own_cycle_r2

__all__ = ["agreeing_cycle_r2", "own_cycle_r2", "own_cycle_veto"]


def agreeing_cycle_r2(cycles: CycleSupport, factors: VarianceFactors | None) -> tuple[np.ndarray, np.ndarray,
                                                                                          bool]:
    """The agreeing cycles' squared errors on the model the loops are judged on: (r2, index into the pairs,
    propagated). With split 3D factors, on the calibrated covariance: s_t S_T + s_r S_R of the decomposed
    (propagated) cycles where the calibration computed them, else the summed covariance's blocks scaled; without
    them, the stated r2 (planar graphs are judged on the stated information with a scaled threshold)."""
    if factors is None:
        return np.asarray(cycles.r2, float), np.arange(len(cycles.r2)), False
    e = np.asarray(cycles.errors, float)
    if cycles.from_translation is not None and cycles.from_rotation is not None:
        sel = np.asarray(cycles.decomposed)
        s = factors.translation * np.asarray(cycles.from_translation) + factors.rotation * np.asarray(
            cycles.from_rotation)
        e = e[sel]
        return np.einsum("ni,ni->n", e, np.linalg.solve(s, e[..., None])[..., 0]), sel, True
    w = 1.0 / np.sqrt(np.r_[np.full(3, factors.translation), np.full(3, factors.rotation)])
    e = e * w
    s = np.asarray(cycles.covariances, float)
    return np.einsum("ni,ni->n", e, np.linalg.solve(s, e[..., None])[..., 0]), np.arange(len(e)), False


def own_cycle_veto(data: PoseGraphData, cycles: CycleSupport, factors: VarianceFactors | None, inlier: np.ndarray,
                   c2: np.ndarray, floor: np.ndarray, quantile: float, window: int, min_cycles: int
                   ) -> tuple[np.ndarray, str | None]:
    """Kept short-span loops to drop (mask, loop order) and a note: those whose own cycle (`own_cycle_r2`) is above
    the `quantile` of the agreeing cycles between kept loops not dropped (`agreeing_cycle_r2`), clipped per loop to
    [`floor`, `c2`] (the chi-square quantile and the loop's threshold, in the units of the judged model). None for
    the note when there is nothing to judge (fewer than `min_cycles` such cycles or no kept short loop).

    A dropped loop's own cycles are not in the reference: a kept false loop that agrees with a kept neighbour (its
    cycle with it as bad as its own) would otherwise set the reference it is judged by (intel local-grouped 50 %,
    seed 5: a group's two kept loops at 2.6 in stated units raised the largest from 1.2 to 2.9). Found from
    below: first without the cycles of any kept short-span loop, then without those of the loops dropped under
    that reference, until the dropped set is stable (it only shrinks: each round's reference holds more cycles)."""
    inlier = np.asarray(inlier, bool)
    out = np.zeros(len(inlier), bool)
    a, b = data.edge_index_pairs()
    idx = data.loop_edges()
    # at most `window` steps: the odometry of a pair cycle is at most `window` steps at each end, so the lever arms
    # a summed covariance leaves out (planar graphs) are as long in both; at 2 x `window` a lap graph's true loops
    # (20 steps, 0.01 rad per step) sat at 1.6x the largest pair cycle and were dropped
    short = inlier & (np.abs(a[idx] - b[idx]) <= max(int(window), 0))
    if not short.any() or len(cycles.r2) == 0:
        return out, None
    r2, sel, propagated = agreeing_cycle_r2(cycles, factors)
    p, q = cycles.P[sel], cycles.Q[sel]
    kept = inlier[p] & inlier[q]
    if int(kept.sum()) < min_cycles:
        return out, None
    judged = data if factors is None else scale_information(data, factors)
    loops = np.flatnonzero(short)
    own = own_cycle_r2(judged, loops, propagate=propagated)
    drop = np.ones(len(loops), bool)
    for _ in range(len(loops) + 1):
        out[:] = False
        out[loops[drop]] = True
        ref_cycles = kept & ~out[p] & ~out[q]
        if int(ref_cycles.sum()) < min_cycles:
            ref_cycles = kept
        ref = float(np.quantile(r2[ref_cycles], quantile))
        new = own > np.clip(ref, floor[loops], c2[loops])
        if np.array_equal(new, drop):
            break
        drop = new
    out[:] = False
    out[loops[drop]] = True
    note = (f"own-cycle test: {int(drop.sum())} of {len(loops)} kept short-span loops dropped (reference {ref:.3g}: "
            f"the {quantile:g} quantile of {int(ref_cycles.sum())} agreeing cycles of kept loops)")
    return out, note
