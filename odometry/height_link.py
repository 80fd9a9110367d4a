"""A redundant height link: a new keyframe's height measured against the keyframe before the last one, too.

The camera height of a keyframe k is a chain (`odometry.height`): its height relative to keyframe k-1, measured
by the tilt refinement, added to k-1's. Each link's error passes unseen into every later keyframe. When the view
of keyframe k-2 still overlaps frame k, the refinement can measure k's height against k-2 directly (link b).
With the two links a_{k-1} (k-2 -> k-1) and a_k (k-1 -> k) they form a triangle:

    path A: (L_{k-1} - L_{k-2}) + a_k,  variance v_A = var(L_{k-1} - L_{k-2}) + var(a_k)
    path B: b,                          variance v_B = var(b)

both the log height of k over k-2. Their inverse-variance mean is the fused step, the keyframe's log height is
L_{k-2} plus it. Its variance stays the single chain's (path A's), unless `shrink_variance`: the fused variance
holds only when the two paths' errors are independent, and an error of frame k's own view (a tilt that couples
into the height, as in our simulator) is common to both and unseen by the triangle; the height tracker
(`odometry.height`) then trusts the chain too much. The disagreement D = A - B is what the single chain cannot see:
D^2 / (v_A + v_B) is 1 on average when the links' variances are honest. Its running mean (the links' NEES,
started from `prior_triangles` triangles at 1, so a few early triangles do not decide it) scales the gate a
triangle must pass: link b is used only when |D| <= gate * sqrt(NEES * (v_A + v_B)) (LK on k-2's corners can
settle at a wrong place when little of its view is left). The variances themselves are not inflated by the
NEES: the fused value's weights depend only on their ratio.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from odometry.height import Height

__all__ = ["HeightLinks", "Triangle"]


@dataclass(frozen=True)
class Triangle:
    """One fused triangle: the disagreement `d` of the two paths (log height), its predicted variance, and whether
    link b passed the gate."""

    d: float
    variance: float
    used: bool


class HeightLinks:
    """Fuse a keyframe's chained height (via k-1) with its redundant measurement (via k-2).

    >>> links = HeightLinks(prior_triangles=5, gate=3.0)
    >>> fused = links.fuse(h_k2, h_k1, via_k1, via_k2)   # Heights; via_k2 None: the chain alone
    """

    def __init__(self, prior_triangles: float = 5.0, gate: float = 3.0, shrink_variance: bool = False) -> None:
        self.prior_triangles = float(prior_triangles)
        self.gate = float(gate)
        # the fused variance assumes the two paths' errors independent; an error of frame k's own view (its tilt
        # coupled into its height) is common to both and unseen by the triangle, so by default the keyframe keeps
        # the single chain's variance (what the height tracker's shrinkage is built on)
        self.shrink_variance = bool(shrink_variance)
        self._sum_z = 0.0      # sum of D^2 / predicted variance over the triangles used
        self.used = 0          # triangles whose link b was fused
        self.rejected = 0      # triangles whose link b failed the gate
        self.last: Triangle | None = None

    @property
    def nees(self) -> float:
        """The links' normalised squared disagreement, shrunk toward 1 by the prior triangles."""
        return (self.prior_triangles + self._sum_z) / (self.prior_triangles + self.used)

    def fuse(self, k2: Height, k1: Height, via_k1: Height, via_k2: Height | None) -> Height:
        """The height of keyframe k: `via_k1` (k-1's height moved by link a_k) fused with `via_k2` (k-2's height
        moved by link b); `k2`, `k1` are the heights of keyframes k-2 and k-1."""
        if via_k2 is None:
            self.last = None
            return via_k1
        step_a = via_k1.log_rel - k2.log_rel
        # the variance path A accumulated since k-2 (k-1's own may have been fused, so never below link a_k's)
        var_a = max(via_k1.variance - k2.variance, via_k1.variance - k1.variance, 0.0)
        step_b = via_k2.log_rel - k2.log_rel
        var_b = max(via_k2.variance - k2.variance, 0.0)
        total = var_a + var_b
        d = step_a - step_b
        if total <= 0.0 or not math.isfinite(total) or not math.isfinite(d):
            self.last = None
            return via_k1
        z = d * d / total
        if z > self.gate ** 2 * self.nees:
            self.rejected += 1
            self.last = Triangle(d, total, False)
            return via_k1
        self.used += 1
        self._sum_z += z
        self.last = Triangle(d, total, True)
        step = (step_a * var_b + step_b * var_a) / total
        var = var_a * var_b / total
        if not self.shrink_variance:
            return Height(k2.metres * math.exp(step), k2.log_rel + step, via_k1.variance, via_k1.tilt)
        return Height(k2.metres * math.exp(step), k2.log_rel + step, k2.variance + var, via_k1.tilt)
