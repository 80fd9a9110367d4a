"""The camera height of a downward VO, frame by frame: measured relative changes, anchored to the nominal height,
used in proportion to how well the data show a departure from it.

A height error is a scale error of every motion. The planar refinement (`odometry.tilt_refine`) measures each
frame's height relative to its keyframe (the scale change of the view, the tilts marginalised, with its variance).
Within a keyframe that ratio is already applied; what is left is the keyframe's own height. Chaining the ratios
gives every frame's height relative to the first frame (`Height.log_rel`), but the absolute level is not
observable from images, and the chain's errors add up like a random walk. So:

- the nominal `camera_height` is taken to be the mean height over the last `window` seconds (a bounce, floor
  unevenness or an altitude hold average out over that time): the departure of a frame is
  d = log_rel - mean(log_rel over the window);
- how much of d is used (`graded`, the default of the VO): the posterior mean under a zero-mean prior on the
  departure, d * S^2 / (S^2 + sigma_d^2), with sigma_d^2 the variance the chain accumulated over the window (the
  links' own variances, from the refinement) plus, before the window is full, the uncertainty of the anchor (its
  missing share times the spread of the heights seen so far: the first frame's own departure is not known), and
  S^2 the spread the heights really have over the window (their spread less what the chain's random walk alone
  may make: `noise_spread` times its variance V over the window). A camera whose height does not vary keeps
  (close to) the nominal height, one that bounces or climbs gets it followed as far as it is measured.
  Two options (off by default: each made our simulator's runs worse, see docs/odometry.md item 10):
  `random_walk_sigma` counts in sigma_d^2 only what a random walk of variance V strays from its own window mean
  (V / 3 once the window is full, V (1 - f + f^2 / 3) at a filled share f), which is exact when the links'
  variances are honest (the independent renderer: link NEES ~1) and too little when they are too small (our
  simulator: ~4x); `start_sigma` gives the anchor's missing share the first frame's own uncertainty about the
  nominal height ((1 - f)^2 start_sigma^2) instead of the spread seen so far, and S^2 becomes the heights' second
  moment about the anchor (the spread of a short stretch about its own mean hides how far it is from the nominal
  level);
- the chain's variance (`Height.variance`) is the sum of the links' variances, each the refinement's marginal
  one, which counts the tilts it leaves to its priors as independent between the two frames of a link. With
  `Height.moved_coupled` (VOConfig.height_tilt_coupling) the tilt part is a wobble shared over time instead
  (consecutive links share the keyframe between them; the frames of a link are ~0.1-0.6 s apart against a
  correlation time of seconds), its standard deviation estimated from the tilts the refinement measures
  (`WobbleEstimate`: ~0 for a camera that does not tilt);
- or, without `graded`, a hard switch: d is used only when |d| > `significance` * sigma_d, else the keyframe is
  put at the nominal height. It throws away real departures below the threshold (up to ~0.6 % on a planks floor
  whose links are poorly measured in turns) and uses the noisy ones above it in full.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

__all__ = ["Height", "HeightTracker", "WobbleEstimate"]


@dataclass(frozen=True)
class Height:
    """A frame's camera height: `metres` (used for its geometry), `log_rel` = log of its height relative to the
    first frame (chained measurements) and `variance` of log_rel (the sum of the chained links' variances)."""

    metres: float
    log_rel: float = 0.0
    variance: float = 0.0
    # the frame's estimated roll and pitch (rad) from the tilt refinement that measured its height: the prior mean
    # of its tilt when it is refined again (as a keyframe) and, decayed, of the next frame's (VOConfig.carry_tilt)
    tilt: tuple[float, float] = (0.0, 0.0)
    # with a tilt wobble correlated over time (`moved_coupled`): the tilt gains of every link chained so far,
    # per axis (roll, pitch), each decayed by exp(-age / wobble_time) to the time `t` of this frame
    tilt_sum: tuple[float, float] = (0.0, 0.0)
    t: float | None = None

    def moved(self, ratio_minus_one: float, variance: float) -> Height:
        """The height of a frame measured at (1 + s) times this one, with the variance of s."""
        s = max(ratio_minus_one, -0.5)   # a refinement gone astray must not flip the sign of the scale
        return Height(self.metres * (1.0 + s), self.log_rel + math.log1p(s), self.variance + max(variance, 0.0))

    def moved_coupled(self, ratio_minus_one: float, data_variance: float, gain: Sequence[float], t: float,
                      wobble_sigma: float, wobble_time: float) -> Height:
        """`moved`, with the link's tilt part counted for a wobble that is shared between frames.

        The link's error from the tilts the data leave to the priors is -gain . tilt (gain: d s / d tilt of
        roll_ref, pitch_ref, roll_cur, pitch_cur, `TiltFit.height_tilt_gain`). The refinement's variance counts
        that part as if the two frames' tilts were independent. A real wobble is slow (correlation
        exp(-dt / wobble_time) per axis): the two frames of a link share most of it, and so do consecutive links
        (a keyframe is the current frame of one link and the reference of the next). So the link's variance is its
        image-noise part (`data_variance`, `TiltFit.height_variance_data`) plus the covariance of its tilt part with
        itself and everything chained before: wobble_sigma^2 times the sum over pairs of gains times their
        correlation, accumulated through the decayed sum `tilt_sum` (exact for that correlation).
        """
        g = [float(x) for x in gain]
        rho = math.exp(-(t - self.t) / wobble_time) if self.t is not None and wobble_time > 0 else 0.0
        acc = [0.0, 0.0]
        coupled = 0.0
        for a in range(2):   # roll, pitch: independent axes
            g_ref, g_cur = g[a], g[2 + a]
            before = self.tilt_sum[a] if self.t is not None else 0.0   # at the keyframe's time: the reference's
            coupled += g_ref * g_ref + 2.0 * g_ref * before
            coupled += g_cur * g_cur + 2.0 * rho * g_cur * (before + g_ref)
            acc[a] = rho * (before + g_ref) + g_cur
        link = max(data_variance, 0.0) + wobble_sigma * wobble_sigma * coupled
        h = self.moved(ratio_minus_one, 0.0)
        # the chain's accumulated variance cannot fall (a negative cross term only takes back what a correlated
        # earlier link added)
        return replace(h, variance=max(self.variance + link, self.variance), tilt_sum=(acc[0], acc[1]), t=float(t))

class HeightTracker:
    """The time window of chained relative heights and the rule (graded shrinkage or significance switch) that
    anchors a keyframe.

    >>> tr = HeightTracker(0.5, window=10.0, significance=3.0, graded=True)
    >>> tr.observe(t, frame_height)            # every frame
    >>> kf_height = tr.anchor(frame_height)    # when the frame starts a keyframe
    """

    def __init__(self, nominal: float, window: float, significance: float, graded: bool = False,
                 noise_spread: float = 1.0, random_walk_sigma: bool = False,
                 start_sigma: float | None = None) -> None:
        self.nominal = float(nominal)
        self.window = float(window)
        self.significance = float(significance)
        self.graded = bool(graded)
        # the share of the window's chained variance V taken to be noise in the heights' spread: a random walk of
        # variance V spreads about its mean by V / 6 on average, but the links' own variances can be too small
        # (NEES ~4 on our simulator, whose tilt wobble couples to the height), so all of V by default
        self.noise_spread = float(noise_spread)
        self.random_walk_sigma = bool(random_walk_sigma)
        # relative standard deviation of the first frame's height about the nominal one (the graded estimate's
        # anchor before the window is full); None: the spread of the heights seen so far
        self.start_sigma = None if start_sigma is None else float(start_sigma)
        self._frames: deque[tuple[float, float, float]] = deque()  # (t, log_rel, variance)
        self._sum = 0.0
        self._sum2 = 0.0
        self._first_t: float | None = None
        self.tracked = 0    # keyframes put at a measured height (graded: any non-zero share of the departure)
        self.nominal_keyframes = 0  # keyframes left at the nominal height (no significant departure)
        self.largest_departure = 0.0  # the largest |log(height / nominal)| given to a keyframe

    def observe(self, t: float, height: Height) -> None:
        """Add a frame's chained height; frames older than the window drop out of the mean."""
        if self._first_t is None:
            self._first_t = float(t)
        self._frames.append((float(t), height.log_rel, height.variance))
        self._sum += height.log_rel
        self._sum2 += height.log_rel ** 2
        while len(self._frames) > 1 and self._frames[0][0] < t - self.window:
            old = self._frames.popleft()[1]
            self._sum -= old
            self._sum2 -= old ** 2

    def departure(self, height: Height) -> tuple[float, float]:
        """(d, sigma_d): log of the frame's height over the window's mean height, and its standard deviation."""
        return self._departure(height)[:2]

    def _departure(self, height: Height) -> tuple[float, float, float]:
        """(d, sigma_d, S^2) of the significance switch: the departure, its standard deviation (the chain's variance
        over the window plus the anchor's missing share times the heights' spread so far), and the heights' spread
        over the window less the chain's noise."""
        if not self._frames:
            return 0.0, math.inf, 0.0
        full, mean, spread2, chain = self._window(height)
        var = chain + (1.0 - full) ** 2 * spread2
        signal = max(spread2 - self.noise_spread * chain, 0.0)
        return height.log_rel - full * mean, math.sqrt(var), signal

    def _window(self, height: Height) -> tuple[float, float, float, float]:
        """(f, mean, spread^2, V): the filled share of the window, the mean and spread of its chained log heights,
        and the variance the chain accumulated over it up to `height`."""
        # before the window is full its mean is a poor estimate of the nominal level: the prior (the first frame's
        # departure is unknown and zero-mean, so the first frame is at the nominal height) keeps the missing share
        full = min(1.0, (self._frames[-1][0] - self._first_t) / self.window)
        n = len(self._frames)
        mean = self._sum / n
        spread2 = max(self._sum2 / n - mean * mean, 0.0)
        chain = max(height.variance - self._frames[0][2], 0.0)
        return full, mean, spread2, chain

    def _graded_terms(self, height: Height) -> tuple[float, float, float]:
        """(d, sigma_d^2, S^2) of the graded estimate (see the module docstring)."""
        full, mean, spread2, chain = self._window(height)
        # d = chain now - f * window mean: the chain's error (all of V, or what a random walk strays from its window
        # mean), and what the anchor's missing share (the first frame's departure) may be off by
        noise = (1.0 - full + full * full / 3.0) * chain if self.random_walk_sigma else chain
        if self.start_sigma is None:
            var = noise + (1.0 - full) ** 2 * spread2
            second = spread2
        else:
            var = noise + ((1.0 - full) * self.start_sigma) ** 2
            # the heights' spread about the nominal level (the anchor), not about their own mean
            second = spread2 + ((1.0 - full) * mean) ** 2
        signal = max(second - self.noise_spread * chain, 0.0)
        return height.log_rel - full * mean, var, signal

    def graded_departure(self, height: Height) -> float:
        """The departure shrunk toward the nominal height by inverse variances, d * S^2 / (S^2 + sigma_d^2): the
        posterior mean of the frame's log height over the nominal one, under a zero-mean prior of variance S^2."""
        if len(self._frames) <= 1:
            return 0.0
        if not self.random_walk_sigma and self.start_sigma is None:
            d, sigma, signal = self._departure(height)   # the default, as it always was computed
            var = sigma * sigma
        else:
            d, var, signal = self._graded_terms(height)
        if signal <= 0.0 or not math.isfinite(var):
            return 0.0
        return d * signal / (signal + var)

    def anchor(self, height: Height) -> Height:
        """The height a new keyframe started by this frame is given: the graded departure from the nominal height
        (`graded`), or the departure when it is significant, else the nominal height (the chain itself is kept
        either way)."""
        if self.graded:
            d = self.graded_departure(height)
            if d == 0.0:
                self.nominal_keyframes += 1
                return replace(height, metres=self.nominal)
            self.tracked += 1
            self.largest_departure = max(self.largest_departure, abs(d))
            return replace(height, metres=self.nominal * math.exp(d))
        d, sigma = self.departure(height)
        if len(self._frames) > 1 and abs(d) > self.significance * sigma:
            self.tracked += 1
            self.largest_departure = max(self.largest_departure, abs(d))
            return replace(height, metres=self.nominal * math.exp(d))
        self.nominal_keyframes += 1
        return replace(height, metres=self.nominal)


class WobbleEstimate:
    """The standard deviation of the camera's real tilt wobble, from the tilts the refinement estimates.

    Each estimate is the posterior mean under the zero-mean prior of standard deviation `prior_sigma`: with a
    posterior variance P its gain is K = 1 - P / prior^2 and its noise n^2 = P / K, so for a wobble of variance
    w^2, E[estimate^2] = K^2 (w^2 + n^2) = K^2 w^2 + K P. Pooled over every estimate, w^2 = (sum estimate^2 -
    sum K P) / sum K^2, starting from `prior_weight` estimates at the prior's own variance (a few early frames do
    not decide it). A camera that does not tilt gets ~0; a wobbling robot about its wobble.
    """

    def __init__(self, prior_sigma: float, prior_weight: float) -> None:
        self.prior_sigma = float(prior_sigma)
        self.prior_weight = float(prior_weight)
        self._sum2 = 0.0
        self._sum_kp = 0.0
        self._sum_k2 = 0.0

    def add(self, estimates: Sequence[float], variances: Sequence[float]) -> None:
        """Add tilt estimates (rad) with their posterior variances (rad^2)."""
        s2 = self.prior_sigma ** 2
        if s2 <= 0.0:
            return
        for est, var in zip(estimates, variances):
            k = min(max(1.0 - float(var) / s2, 0.0), 1.0)
            self._sum2 += float(est) ** 2
            self._sum_kp += k * float(var)
            self._sum_k2 += k * k

    @property
    def sigma(self) -> float:
        num = self.prior_weight * self.prior_sigma ** 2 + self._sum2 - self._sum_kp
        den = self.prior_weight + self._sum_k2
        return math.sqrt(max(num, 0.0) / den) if den > 0.0 else self.prior_sigma
